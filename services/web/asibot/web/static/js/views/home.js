// Home tab: what this page is for, the robot it commands, and the Task Creator wizard.
import { api, chosenRobot, paths } from '../api.js';
import { attempt, el, notify } from '../ui.js';
import { startWizard } from '../wizard.js';
import { favouritesPanel } from '../favourites.js';
import { describe } from '../scanning.js';
import { onSettings, settings, update as updateSettings } from '../settings.js';

// Switch access, found where a carer starts: on or off in one action, for the person's tasks and
// places (the Access page has every other setting).
function switchAccess() {
  const says = el('p', { role: 'status' });
  const button = el('button', { type: 'button', class: 'primary big' });
  const sync = (s) => {
    says.textContent = s.enabled
      ? `Switch scanning is on: ${describe(s)}. Press your switch (${s.next.label}) to start the ring.`
      : 'For a person who uses one or two switches (a big button, a head switch) or a key: a ring goes over '
        + 'the tasks and places above, the Emergency stop first, and the switch chooses. Tap Space to move, hold it to choose; '
        + 'two quick taps stop every robot.';
    button.textContent = s.enabled ? 'Turn switch scanning off' : 'Turn switch scanning on';
  };
  button.addEventListener('click', () => {
    const on = !settings().enabled;
    updateSettings(on ? { enabled: true, scope: 'home' } : { enabled: false });
    notify(on ? 'Switch scanning is on, for your tasks and places. The Access page has its other settings.'
      : 'Switch scanning is off.', 'info');
  });
  sync(settings());
  const off = onSettings(sync);
  const node = el('section', { class: 'panel', 'aria-label': 'Switch access' }, el('h2', {}, 'Switch access'), says,
    el('div', { class: 'row' }, button, el('a', { href: '#access', class: 'button-link' }, 'All access settings')));
  return { node, unmount: off };
}

export default {
  mount(root) {
    const status = el('p', { class: 'big', role: 'status' });
    const mine = favouritesPanel();
    const access = switchAccess();
    root.replaceChildren(mine.node,
      el('section', { class: 'panel' },
        el('h2', {}, 'Teach the robot a task'),
        el('p', {}, 'Move the arm, capture the points it should visit, write a short program with them, ',
          'give it a word and an icon, and launch it from the Launcher with one touch.'),
        status,
        el('div', { class: 'row' },
          el('button', { type: 'button', class: 'primary big', onclick: startWizard }, 'Start the Task Creator wizard'),
          el('a', { href: '#launcher', class: 'button-link' }, 'Go to the Launcher'))),
      access.node,
      el('section', { class: 'panel' },
        el('h2', {}, 'Safety'),
        el('p', {}, 'The red Emergency stop button at the top, or the Esc key, stops every robot and the running program at once; ',
          'with switch scanning, so do two quick taps of the switch. Release all, next to it, lets them move again; ',
          'nothing moves until you ask it to.'),
        el('p', { id: 'esc-rule' }, 'The Esc key: one Esc stops. In a text field or the program editor, or when Esc closes something ',
          '(the editor\'s list of completions, its search box, a name being changed), the first Esc only does that and the ',
          'button at the top says "Esc again: emergency stop"; the second Esc stops. So two Esc presses in a row always stop.')));
    const upload = el('input', { type: 'file', accept: '.zip,application/zip', 'aria-label': 'Import ASIBOT user files (a zip)' });
    const report = el('div', { role: 'status' });
    upload.addEventListener('change', () => attempt(async () => {
      const form = new FormData();
      form.append('file', upload.files[0]);
      const r = await api.post(paths.importFiles, form);
      upload.value = '';
      report.replaceChildren(
        el('p', {}, `Imported: ${r.imported.length ? r.imported.join(', ') : 'nothing'}.`),
        r.skipped.length ? el('p', {}, `Left out: ${r.skipped.map((s) => `${s.item} (${s.reason})`).join('; ')}.`) : null,
        ...r.notes.map((n) => el('p', { class: 'muted' }, n)));
      return r;
    }, (r) => `${r.imported.length} files imported.`));
    root.append(el('section', { class: 'panel', 'aria-label': 'Your files' },
      el('h2', {}, 'Your files'),
      el('p', {}, 'Points, programs, words, tasks and icons, in the formats of the original ASIBOT Task Creator ',
        '(points.ini, words.ini, <task>.task), so an existing user\'s files load.'),
      el('div', { class: 'row' },
        el('a', { href: paths.exportFiles, download: 'asibot-user-files.zip', class: 'button-link' }, 'Export my files'),
        el('label', {}, 'Import ASIBOT files: ', upload)),
      report));
    // A phone or a tablet: the address (and its QR code) when the page serves the LAN.
    const phone = el('section', { class: 'panel', 'aria-label': 'Phone or tablet' }, el('h2', {}, 'Use a phone or a tablet'));
    root.append(phone);
    api.get(paths.phone).then((p) => {
      phone.append(el('p', {}, p.text));
      if (!p.lan) return;
      phone.append(el('img', { class: 'qr', src: paths.phoneQr, width: '264', height: '264',
        alt: `QR code of the address ${p.urls[0]}` }));
      for (const url of p.urls) phone.append(el('p', { class: 'readout' }, url));
    }).catch((e) => phone.append(el('p', {}, `How to reach this page from a phone is not known: ${e.message}`)));
    const update = () => {
      const r = chosenRobot();
      status.textContent = r ? `Commanding ${r.id} (${r.simulated ? 'simulated' : 'real'} ${r.arm || 'robot'}).`
        : 'No robot commanded yet: press Command beside one in the Connection Manager at the top.';
    };
    return { update, unmount: () => { mine.unmount(); access.unmount(); } };
  },
};
