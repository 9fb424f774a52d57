// The Program tab's steps editor: a program as a list of steps (move to a captured point, open or
// close the gripper, wait, say, repeat), for people who write no Python. Each step is a row with
// the server's plain sentence ("Move above grasp-can (joint move)") and buttons to edit it, move it
// up or down and remove it; buttons add each kind of step (a point is always chosen from the
// captured ones, never typed), and "Pick it up…" / "Put it down…" add a template's steps from one
// point. The steps being edited stay in the page until Save steps, which writes the program's
// Python from them on the server (web/steps.py makes it); "Show as Python" shows that code. A
// program whose Python was edited after its steps made it says so: both are kept, and saving the
// steps again asks first, since it replaces that Python (kept as a previous version).
// Every control is a real <button> (or a labelled field) with visible text: touch, keyboard and
// the one-switch scanner (scanning.js) reach each one.
import { api, paths } from './api.js';
import { loadPoints, onPointsChange } from './points.js';
import { attempt, confirmable, el, notify } from './ui.js';

const HOW = [['auto', 'Chosen for me'], ['joint', 'Joint move'], ['straight', 'Straight move']];

// A new step of each kind, as the server's models take it (web/steps.py).
const NEW = {
  open: () => ({ kind: 'open' }),
  close: () => ({ kind: 'close', check: true }),
  wait: () => ({ kind: 'wait', seconds: 1 }),
  say: () => ({ kind: 'say', text: 'Here you are.' }),
  repeat: () => ({ kind: 'repeat', times: 2, steps: [] }),
};

// The list of steps at `path` ([] the program's; [3] inside step 4, a Repeat) and the step at `path`.
const listAt = (steps, path) => path.reduce((list, i) => list[i].steps, steps);
const stepAt = (steps, path) => listAt(steps, path.slice(0, -1))[path[path.length - 1]];
const number = (path) => path.map((i) => i + 1).join('.');
const samePath = (a, b) => a !== null && b !== null && a.length === b.length && a.every((x, i) => x === b[i]);

// What a row says while the server has not described it (a point it names is gone).
function plain(step) {
  if (step.kind === 'move') return `Move ${step.above ? 'above' : 'to'} ${step.thing ? `the ${step.thing}` : step.point}`;
  if (step.kind === 'find') return `Look for the ${step.thing.name}`;
  if (step.kind === 'repeat') return `Repeat ${step.times} times`;
  if (step.kind === 'wait') return `Wait ${step.seconds} s`;
  if (step.kind === 'say') return `Say “${step.text}”`;
  return step.kind === 'open' ? 'Open the gripper' : 'Close the gripper';
}

// The editor; `onSaved(name)` after the steps wrote the program's Python, `showPython()` to
// switch the tab to the Python editor.
export function stepsEditor({ onSaved, showPython }) {
  let name = null;          // the program shown
  let steps = [];           // the steps being edited
  let described = null;     // the server's sentences of `steps` (null: not known)
  let hasSteps = false;     // the program is saved as steps (else it is written in Python)
  let inSync = true;        // its Python is the one its saved steps made
  let pointsChanged = false;
  let dirty = false;        // `steps` differ from the saved ones
  let target = [];          // where new steps go: the program's list, or inside a Repeat
  let editing = null;       // the path of the step whose fields are open
  let choosing = null;      // { what, then(point) }: the point chooser is open
  let points = [];
  let previewed = 0;        // the newest preview asked for (older answers are dropped)
  let focusKey = null;      // the control to focus after the next draw

  const status = el('p', { class: 'steps-status', role: 'status' });
  const problem = el('p', { class: 'steps-problem', role: 'alert', hidden: true });
  const list = el('ol', { class: 'steps', 'aria-label': 'Steps' });
  const adders = el('div', { class: 'chips', role: 'group', 'aria-label': 'Add a step' });
  const where = el('p', { class: 'steps-where' });
  const chooser = el('div', { class: 'steps-chooser', role: 'group', 'aria-label': 'Choose a point', hidden: true });
  const code = el('pre', { class: 'steps-python', tabindex: '0', role: 'region', 'aria-label': 'The program as Python', hidden: true });
  const showCode = el('button', { type: 'button', 'aria-expanded': 'false', onclick: () => togglePython() }, 'Show as Python');
  const save = confirmable('Save steps', { class: 'primary', 'aria-label': 'Save steps' }, () => saveSteps(),
    { ask: 'Sure? It replaces the Python: touch again', needed: () => !inSync });
  const discard = el('button', { type: 'button', onclick: () => name && attempt(() => open(name), 'Back to the saved steps.') }, 'Discard changes');

  const focusable = (key, node) => { node.dataset.focus = key; return node; };

  // --- the server ---------------------------------------------------------------------------
  const preview = async () => {
    const asked = ++previewed;
    try {
      const r = await api.post(paths.programSteps.preview(name), { steps });
      if (asked !== previewed) return;
      described = r.described;
      problem.hidden = true;
      if (!code.hidden) code.textContent = r.text;
    } catch (e) {
      if (asked !== previewed) return;
      described = null;
      problem.textContent = e.message;
      problem.hidden = false;
    }
    // A redraw would replace a step's field while it is typed in, and lose what was typed:
    // then only the sentences are brought up to date (the field's change describes it again).
    const typing = list.contains(document.activeElement) && document.activeElement.matches('input, select, textarea');
    if (typing) sayAgain(steps, described, []); else draw();
  };
  const changed = () => { dirty = true; draw(); preview(); };

  async function open(program) {
    const r = await api.get(paths.programSteps.steps(program));
    name = program;
    hasSteps = r.steps !== null;
    steps = r.steps || [];
    described = r.described;
    inSync = r.in_sync;
    pointsChanged = r.points_changed;
    dirty = false;
    target = [];
    editing = null;
    choosing = null;
    problem.hidden = true;
    code.hidden = true;
    showCode.setAttribute('aria-expanded', 'false');
    draw();
    return r;
  }

  const saveSteps = () => name && attempt(async () => {
    const r = await api.put(paths.programSteps.steps(name), { steps, replace_python: !inSync });
    steps = r.steps;
    described = r.described;
    hasSteps = true;
    inSync = true;
    pointsChanged = false;
    dirty = false;
    problem.hidden = true;
    if (!code.hidden) code.textContent = r.text;
    draw();
    await onSaved(name);
    return r;
  });   // no notice: the status line (role=status) says "Steps saved" and is read out

  async function togglePython() {
    if (!code.hidden) {
      code.hidden = true;
      showCode.setAttribute('aria-expanded', 'false');
      return;
    }
    await attempt(async () => {
      const r = await api.post(paths.programSteps.preview(name), { steps });
      code.textContent = r.text;
      code.hidden = false;
      showCode.setAttribute('aria-expanded', 'true');
      code.focus();
    });
  }

  // --- changing the steps -------------------------------------------------------------------
  const add = (...added) => {
    const into = listAt(steps, target);
    into.push(...added);
    const last = [...target, into.length - 1];
    if (added.length === 1 && added[0].kind === 'repeat') {
      target = last;       // what comes next goes inside the new Repeat
    }
    if (added.length === 1 && ['wait', 'say', 'repeat'].includes(added[0].kind)) editing = last;
    focusKey = `${number(last)}:row`;
    changed();
  };
  const move = (path, by) => {
    const into = listAt(steps, path.slice(0, -1));
    const i = path[path.length - 1];
    const j = i + by;
    if (j < 0 || j >= into.length) return;
    [into[i], into[j]] = [into[j], into[i]];
    const moved = [...path.slice(0, -1), j];
    if (editing && samePath(editing, path)) editing = moved;
    if (samePath(target.slice(0, path.length), path)) target = [...moved, ...target.slice(path.length)];
    else if (samePath(target.slice(0, path.length), moved)) target = [...path, ...target.slice(path.length)];
    focusKey = `${number(moved)}:${by < 0 ? 'up' : 'down'}`;
    changed();
  };
  const remove = (path) => {
    listAt(steps, path.slice(0, -1)).splice(path[path.length - 1], 1);
    // Removing a Repeat (or a step before it) moves where new steps go back to the program's end.
    if (target.length >= path.length) target = [];
    editing = null;
    focusKey = 'add:move';
    changed();
  };
  const choose = (what, then) => {
    choosing = { what, then };
    focusKey = 'choose:0';
    draw();
  };
  const template = (kind, label) => choose(`${label} at which point?`, (point) => attempt(async () => {
    const r = await api.post(paths.programSteps.template(name), { template: kind, point });
    add(...r.steps);
  }, `${label}: ${point}.`));

  // --- drawing ------------------------------------------------------------------------------
  const field = (label, input) => el('label', {}, label, ' ', input);
  const fields = (step, path) => {
    const set = (key, value) => { step[key] = value; changed(); };
    const box = el('div', { class: 'row step-fields', role: 'group', 'aria-label': `Step ${number(path)}` });
    if (step.kind === 'move' && step.thing) {
      // A move to a thing goes where the step that looks for it finds it, when it runs.
      const how = el('select', { onchange: (e) => set('how', e.target.value) },
        ...HOW.map(([v, text]) => el('option', { value: v, selected: v === step.how }, text)));
      box.append(el('span', {}, `To the ${step.thing}, where it is found`), field('How', how),
        field('Above it', el('input', { type: 'checkbox', checked: step.above, onchange: (e) => set('above', e.target.checked) })),
        field('Slowly', el('input', { type: 'checkbox', checked: step.slow, onchange: (e) => set('slow', e.target.checked) })));
    } else if (step.kind === 'find') {
      const t = step.thing;
      box.append(el('span', {}, `Looks for the ${t.name}: a ${t.colour} object ${Math.round(t.height * 100)} cm tall, near where it was taught.`));
    } else if (step.kind === 'move') {
      const point = el('select', { onchange: (e) => set('point', e.target.value) },
        ...[...new Set([step.point, ...points.map((p) => p.name)])].map((n) => el('option', { value: n, selected: n === step.point }, n)));
      const how = el('select', { onchange: (e) => set('how', e.target.value) },
        ...HOW.map(([v, text]) => el('option', { value: v, selected: v === step.how }, text)));
      box.append(field('Point', point), field('How', how),
        field('Above the point', el('input', { type: 'checkbox', checked: step.above, onchange: (e) => set('above', e.target.checked) })),
        field('Slowly', el('input', { type: 'checkbox', checked: step.slow, onchange: (e) => set('slow', e.target.checked) })));
    } else if (step.kind === 'close') {
      box.append(field('Check it holds something', el('input', { type: 'checkbox', checked: step.check, onchange: (e) => set('check', e.target.checked) })));
    } else if (step.kind === 'wait') {
      box.append(field('Seconds', el('input', { type: 'number', class: 'narrow', min: '0.1', step: '0.5', value: String(step.seconds),
        onchange: (e) => set('seconds', Number(e.target.value)) })));
    } else if (step.kind === 'say') {
      box.append(field('Text', el('input', { type: 'text', value: step.text, onchange: (e) => set('text', e.target.value) })));
    } else if (step.kind === 'repeat') {
      box.append(field('Times', el('input', { type: 'number', class: 'narrow', min: '1', step: '1', value: String(step.times),
        onchange: (e) => set('times', Math.round(Number(e.target.value))) })));
    } else {
      box.append(el('span', { class: 'muted' }, 'This step has nothing to set.'));
    }
    box.append(focusable(`${number(path)}:done`, el('button', { type: 'button', onclick: () => { editing = null; focusKey = `${number(path)}:edit`; draw(); } }, 'Done')));
    return box;
  };
  // What row `n` says: the server's sentence, or the page's own while it has none.
  const sentence = (n, step, said) => [el('span', { class: 'step-number' }, `${n}.`), ' ', said ? said.sentence : plain(step)];
  const sayAgain = (items, sentences, prefix) => items.forEach((step, i) => {
    const path = [...prefix, i];
    const n = number(path);
    const said = sentences ? sentences[i] : null;
    list.querySelector(`[data-focus="${n}:row"]`)?.replaceChildren(...sentence(n, step, said));
    if (step.kind === 'repeat') sayAgain(step.steps, said ? said.steps : null, path);
  });
  const rows = (items, sentences, prefix) => items.map((step, i) => {
    const path = [...prefix, i];
    const n = number(path);
    const said = sentences ? sentences[i] : null;
    const count = items.length;
    const li = el('li', { class: `step step-${step.kind}`, dataset: { step: n } },
      el('div', { class: 'row' },
        focusable(`${n}:row`, el('span', { class: 'step-sentence', tabindex: '-1' }, ...sentence(n, step, said))),
        el('span', { class: 'step-buttons' },
          focusable(`${n}:edit`, el('button', { type: 'button', 'aria-label': `Edit step ${n}`, 'aria-expanded': String(samePath(editing, path)),
            onclick: () => { editing = samePath(editing, path) ? null : path; focusKey = `${n}:edit`; draw(); } }, 'Edit')),
          focusable(`${n}:up`, el('button', { type: 'button', 'aria-label': `Move step ${n} up`, disabled: i === 0, onclick: () => move(path, -1) }, 'Up')),
          focusable(`${n}:down`, el('button', { type: 'button', 'aria-label': `Move step ${n} down`, disabled: i === count - 1, onclick: () => move(path, 1) }, 'Down')),
          step.kind === 'repeat' ? focusable(`${n}:inside`, el('button', {
            type: 'button', 'aria-label': `Add steps inside step ${n}`, 'aria-pressed': String(samePath(target, path)),
            onclick: () => { target = path; focusKey = 'add:move'; draw(); },
          }, 'Add inside')) : null,
          el('button', { type: 'button', class: 'danger', 'aria-label': `Remove step ${n}`, onclick: () => remove(path) }, 'Remove'))),
      samePath(editing, path) ? fields(step, path) : null);
    if (step.kind === 'repeat') {
      li.append(el('ol', { class: 'steps inner', 'aria-label': `Steps inside step ${n}` },
        ...rows(step.steps, said ? said.steps : null, path)));
    }
    return li;
  });

  function draw() {
    const active = document.activeElement && document.activeElement.dataset ? document.activeElement.dataset.focus : null;
    if (!name) {
      status.textContent = 'Open a program, or make one from steps.';
    } else if (!hasSteps) {
      status.textContent = `${name} is written in Python: it has no steps. Add steps below; saving them replaces its Python (kept as a previous version).`;
    } else if (!inSync) {
      status.textContent = `The Python of ${name} was edited after its steps made it, so the steps no longer match it. Both are kept. `
        + 'Keep working in Python, or save the steps to make the Python from them again (the edited Python is kept as a previous version).';
    } else if (dirty) {
      status.textContent = 'Unsaved changes to the steps: Save steps makes the program from them.';
    } else if (pointsChanged) {
      status.textContent = 'A point these steps use was captured again (or is gone) since they were saved: Save steps to use it as it is now.';
    } else {
      status.textContent = `Steps saved: ${name}.py is made from them.`;
    }
    status.className = `steps-status${!inSync || !hasSteps ? ' out-of-sync' : dirty || pointsChanged ? ' unsaved' : ''}`;
    discard.disabled = !dirty;
    list.replaceChildren(...(steps.length ? rows(steps, described, [])
      : [el('li', { class: 'muted' }, 'No steps yet: add one below, or touch Pick it up… to make the whole pick from one point.')]));
    const inside = target.length ? stepAt(steps, target) : null;
    where.replaceChildren(...(inside ? [
      el('span', {}, `New steps go inside step ${number(target)} (Repeat ${inside.times} times). `),
      focusable('add:end', el('button', { type: 'button', onclick: () => { target = []; focusKey = 'add:move'; draw(); } }, 'Add at the end instead')),
    ] : [el('span', {}, 'New steps go at the end of the program.')]));
    adders.replaceChildren(
      focusable('add:move', el('button', { type: 'button', onclick: () => choose('Move to which point?', (p) => add({ kind: 'move', point: p, how: 'auto', above: false, slow: false })) }, 'Move to a point…')),
      el('button', { type: 'button', onclick: () => add(NEW.open()) }, 'Open gripper'),
      el('button', { type: 'button', onclick: () => add(NEW.close()) }, 'Close gripper'),
      el('button', { type: 'button', onclick: () => add(NEW.wait()) }, 'Wait'),
      el('button', { type: 'button', onclick: () => add(NEW.say()) }, 'Say'),
      el('button', { type: 'button', onclick: () => add(NEW.repeat()) }, 'Repeat'),
      el('button', { type: 'button', class: 'primary', onclick: () => template('pick_it_up', 'Pick it up') }, 'Pick it up…'),
      el('button', { type: 'button', class: 'primary', onclick: () => template('put_it_down', 'Put it down') }, 'Put it down…'));
    for (const b of adders.querySelectorAll('button')) b.disabled = !name;
    chooser.hidden = !choosing;
    if (choosing) {
      const { what, then } = choosing;
      chooser.replaceChildren(el('p', {}, what),
        ...(points.length ? points.map((p, i) => focusable(`choose:${i}`, el('button', {
          type: 'button', 'aria-label': `Choose point ${p.name}`, onclick: () => { choosing = null; then(p.name); if (!choosing) draw(); },
        }, p.name))) : [el('span', { class: 'muted' }, 'No points yet: capture some on the Joint or Cartesian page.')]),
        focusable('choose:cancel', el('button', { type: 'button', onclick: () => { choosing = null; focusKey = 'add:move'; draw(); } }, 'Cancel')));
    }
    const key = focusKey || active;
    focusKey = null;
    if (key) {
      const node = [...root.querySelectorAll('[data-focus]')].find((n) => n.dataset.focus === key);
      if (node) node.focus();
    }
  }

  const off = onPointsChange((data) => { points = data.points; if (choosing || editing) draw(); });
  // Save and its row come after the steps and the adders, as a form's submit does, and stay in
  // sight at the bottom of the window (sticky): the next thing after an edit by Tab or by one switch.
  const root = el('div', { class: 'steps-editor' },
    status,
    problem,
    list,
    el('h3', {}, 'Add a step'),
    where, adders, chooser,
    el('div', { class: 'row steps-actions', role: 'group', 'aria-label': 'Save or discard the steps' },
      save, showCode, discard,
      el('button', { type: 'button', onclick: () => showPython() }, 'Edit as Python')),
    code);
  draw();
  loadPoints().catch((e) => notify(e.message));

  return {
    node: root,
    open,
    close: () => { name = null; steps = []; described = null; hasSteps = false; inSync = true; dirty = false; draw(); },
    dirty: () => dirty,
    inSync: () => inSync,
    save: saveSteps,
    unmount: off,
    // Where a program just made starts being read: its first step, or adding one (no steps yet).
    focusStart: () => (list.querySelector('[data-focus="1:row"]') || root.querySelector('[data-focus="add:move"]'))?.focus(),
  };
}

// The point chooser of the Programs panel: a new program made from a template at a point.
export function pointChooser(box, what, then) {
  box.hidden = false;
  const close = () => { box.hidden = true; box.replaceChildren(); };
  const show = (data) => box.replaceChildren(el('p', {}, what),
    ...(data.points.length ? data.points.map((p) => el('button', {
      type: 'button', 'aria-label': `Choose point ${p.name}`, onclick: () => { close(); then(p.name); },
    }, p.name)) : [el('span', { class: 'muted' }, 'No points yet: capture some on the Joint or Cartesian page.')]),
    el('button', { type: 'button', onclick: close }, 'Cancel'));
  loadPoints().then((data) => { show(data); const first = box.querySelector('button'); if (first) first.focus(); })
    .catch((e) => notify(e.message));
}
