// Access tab: switch scanning and messages, set for this browser (settings.js keeps them), and
// their file to carry them to another browser. Every setting is a row of big buttons or a number
// with − and + buttons, so it can itself be set by scanning.
import { captureSwitch, describe } from '../scanning.js';
import { CHOICES, LIMITS, exportText, importText, onSettings, reset, settings, update } from '../settings.js';
import { api, paths } from '../api.js';
import { FADE_MS, attempt, confirmable, el, notify } from '../ui.js';

const LABELS = {
  enabled: { heading: 'Switch scanning', values: [[false, 'Off'], [true, 'On']] },
  mode: { heading: 'How the ring moves', values: [['step', 'Step: my switch moves it'], ['auto', 'Automatic: it moves by itself']] },
  pattern: { heading: 'Order', values: [['rowcol', 'Row, then column'], ['linear', 'One by one'], ['group', 'Groups']] },
  switches: { heading: 'Switches', values: [[1, 'One switch: tap = next, hold = select'], [2, 'Two switches: next and select']] },
  afterSelect: { heading: 'After a select', values: [['resume', 'The Emergency stop, then where I was'], ['start', 'The Emergency stop, then the top'], ['stay', 'Stay on the control']] },
  sound: { heading: 'Sound', values: [[false, 'Silent'], [true, 'Beep at each step']] },
  scope: { heading: 'What the ring goes over', values: [['page', 'The whole page'], ['home', 'My tasks and places first (Home)']] },
  doubleTapStop: { heading: 'Two quick taps', values: [[true, 'Stop every robot'], [false, 'Move the ring twice']] },
  messages: { heading: 'Good-news messages', values: [['fade', `Fade after ${FADE_MS / 1000} s`], ['stay', 'Stay until I dismiss them']] },
};

function change(patch) {
  try {
    update(patch);
  } catch (e) {
    notify(e.message);
  }
}

// A row of buttons, one pressed: one multiple-choice setting.
function choice(name) {
  const { heading, values } = LABELS[name];
  const buttons = values.map(([value, label]) => el('button', { type: 'button', onclick: () => change({ [name]: value }) }, label));
  const sync = (s) => values.forEach(([value], i) => buttons[i].setAttribute('aria-pressed', String(s[name] === value)));
  return { node: el('div', { class: 'row setting', role: 'group', 'aria-label': heading }, el('span', { class: 'label' }, heading), buttons), sync };
}

// A number with its unit, typed or changed by one step with − and +.
function number(name, heading, unit) {
  const [lo, hi, step] = LIMITS[name];
  const input = el('input', { type: 'number', min: String(lo), max: String(hi), step: String(step), inputmode: 'numeric' });
  input.addEventListener('change', () => {
    change({ [name]: Number(input.value) });
    input.value = String(settings()[name]);    // a refused value goes back to the one in force
  });
  const by = (k) => () => change({ [name]: Math.min(hi, Math.max(lo, settings()[name] + k * step)) });
  input.id = `access-${name}`;
  const node = el('div', { class: 'row setting' },
    el('label', { class: 'label', for: input.id }, `${heading} (${unit ? `${unit}, ` : ''}${lo} to ${hi})`), input,
    el('button', { type: 'button', 'aria-label': `Less: ${heading}`, onclick: by(-1) }, '−'),
    el('button', { type: 'button', 'aria-label': `More: ${heading}`, onclick: by(1) }, '+'));
  return { node, sync: (s) => { if (document.activeElement !== input) input.value = String(s[name]); } };
}

// "Press your switch now": the next key or mouse button becomes the switch `which`.
function switchRow(which) {
  const value = el('strong', { class: 'switch-name' });
  const heading = el('span', { class: 'label' });
  const prompt = el('p', { class: 'capture-prompt', role: 'alert', hidden: true },
    'Press your switch now: a key, or a mouse button anywhere on the page. ');
  const cancel = el('button', { type: 'button' }, 'Cancel');
  prompt.append(cancel);
  let listening = null;
  const changeButton = el('button', {
    type: 'button',
    onclick: () => {
      if (listening) return;
      // Listen from the next tick: the press (or click) that chose Change is not the new switch.
      setTimeout(async () => {
        listening = captureSwitch(cancel);
        prompt.hidden = false;
        const sw = await listening.result;
        listening = null;
        prompt.hidden = true;
        if (!sw) return;
        try {
          update({ [which]: sw });
          notify(`Your ${which === 'next' && settings().switches === 1 ? '' : `${which} `}switch is now ${sw.label}.`, 'info');
        } catch (e) {
          notify(e.message);
        }
      }, 0);
    },
  }, 'Change switch');
  const row = el('div', {}, el('div', { class: 'row setting' }, heading, value, changeButton), prompt);
  const sync = (s) => {
    heading.textContent = which === 'select' ? 'Select switch' : s.switches === 1 ? 'Your switch' : 'Next switch';
    changeButton.setAttribute('aria-label', `Change switch: ${heading.textContent}`);
    value.textContent = s[which].label;
    row.hidden = which === 'select' && s.switches === 1;
  };
  return { node: row, sync, stop: () => listening && listening.stopListening() };
}

// The carer's order of the person's tasks and places on Home (the rest follows by use).
function orderPanel() {
  const list = el('ol', { class: 'points order', 'aria-label': 'Order on Home' });
  const how = el('p', { role: 'status' });
  let items = [];
  const draw = (data) => {
    items = data.items;
    how.textContent = data.order.length ? 'In the order you set; what you did not place follows, most used first.'
      : 'Most used first, as the person uses them. Move one to set the order yourself.';
    const say = (i) => (i.kind === 'task' ? i.name : `Go to ${i.name} (${i.robot})`);
    list.replaceChildren(...items.map((item, n) => el('li', {},
      el('span', { class: 'pname' }, say(item)), el('span', { class: 'muted' }, ` used ${item.uses}×`),
      el('button', { type: 'button', 'aria-label': `Earlier: ${say(item)}`, disabled: n === 0, onclick: () => move(n, -1) }, 'Earlier'),
      el('button', { type: 'button', 'aria-label': `Later: ${say(item)}`, disabled: n === items.length - 1, onclick: () => move(n, 1) }, 'Later'))));
  };
  const put = (order) => attempt(async () => draw(await api.put(paths.favouritesOrder, { order })));
  const move = (n, by) => {
    const keys = items.map((i) => i.key);
    [keys[n], keys[n + by]] = [keys[n + by], keys[n]];
    put(keys);
  };
  api.get(paths.favourites).then(draw).catch((e) => notify(e.message));
  const node = el('section', { class: 'panel', 'aria-label': 'Order on Home' },
    el('h2', {}, 'Order on Home'),
    el('p', {}, 'The person\'s tasks and places, as Home shows them and the ring goes over them: the first ones take the fewest presses.'),
    how, list, el('div', { class: 'row' }, el('button', { type: 'button', onclick: () => put([]) }, 'Order by use')));
  return { node };
}

function download() {
  const url = URL.createObjectURL(new Blob([exportText()], { type: 'application/json' }));
  const a = el('a', { href: url, download: 'asibot-access-settings.json' });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 0);
}

export default {
  mount(root) {
    const how = el('p', { class: 'big', role: 'status' });
    const parts = [choice('enabled'), choice('scope'), choice('mode'), choice('pattern'), choice('switches'), switchRow('next'), switchRow('select'),
      number('intervalMs', 'Scanning time, automatic', 'ms'), number('holdMs', 'Hold to select, one switch', 'ms'),
      number('rounds', 'Rounds before scanning stops', null), choice('afterSelect'), choice('sound'),
      choice('doubleTapStop'), number('doubleTapMs', 'Two quick taps: at most this apart', 'ms'),
      number('holdStopMs', 'A hold this long stops every robot, 0: off', 'ms'),
      number('dwellMs', 'Dwell to choose (eye-gaze, head pointer), 0: off', 'ms')];
    const order = orderPanel();
    const messages = choice('messages');
    const upload = el('input', { type: 'file', accept: '.json,application/json' });
    upload.addEventListener('change', async () => {
      const file = upload.files[0];
      upload.value = '';
      if (!file) return;
      try {
        importText(await file.text());
        notify(`Settings imported from ${file.name}.`, 'info');
      } catch (e) {
        notify(e.message);
      }
    });
    root.replaceChildren(el('div', { class: 'columns' },
      el('section', { class: 'panel', 'aria-label': 'Switch scanning' },
        el('h2', {}, 'Switch scanning'),
        el('p', {}, 'With one or two switches (a key or a mouse button): a yellow and black ring goes over the page, ',
          'the Emergency stop first, and you select what it rings. A long list (a dozen programs) is one stop of the ring: select it to go into it. ',
          'Hold-to-move buttons start on a select and stop on your next press.'),
        how,
        parts.map((p) => p.node)),
      el('div', {},
        order.node,
        el('section', { class: 'panel', 'aria-label': 'Messages' },
          el('h2', {}, 'Messages'),
          el('p', {}, 'Errors stay until you press Dismiss. Good news fades unless you point at it, or you choose “Stay until I dismiss them”.'),
          messages.node),
        el('section', { class: 'panel', 'aria-label': 'Settings file' },
          el('h2', {}, 'Settings file'),
          el('p', {}, 'These settings are kept in this browser. Take them to another browser as a file.'),
          el('div', { class: 'row' },
            el('button', { type: 'button', class: 'primary', onclick: download }, 'Export settings'),
            el('label', {}, 'Import settings: ', upload)),
          el('div', { class: 'row' }, confirmable('Back to the defaults', {}, () => { reset(); notify('Access settings are back to the defaults.', 'info'); }))))));
    const sync = (s) => {
      for (const p of [...parts, messages]) p.sync(s);
      how.textContent = s.enabled ? `Scanning is on: ${describe(s)}.` : 'Scanning is off: the page works by touch, mouse and keyboard as usual.';
    };
    sync(settings());
    const off = onSettings(sync);
    return { unmount: () => { off(); parts.forEach((p) => p.stop && p.stop()); } };
  },
};
