// Taught points: capture the arm's point (also while it moves), rename, delete, and go there
// with one touch. Shared by the Joint and Cartesian pages; the Program page lists them too.
import { api, paths, state } from './api.js';
import { kept, setKept } from './keep.js';
import { attempt, attemptOn, confirmable, el, fmt, notify } from './ui.js';

const listeners = new Set();
export function onPointsChange(fn) { listeners.add(fn); return () => listeners.delete(fn); }
export async function loadPoints() {
  const data = await api.get(paths.points);
  for (const fn of listeners) fn(data);
  return data;
}

function row(point) {
  const li = el('li', { dataset: { point: point.name } });
  const show = () => li.replaceChildren(
    el('span', { class: 'pname' }, point.name),
    el('span', { class: 'pvals' }, point.values.map((v, i) => fmt(v, i < 3 ? 3 : 1)).join('  ')),
    el('button', {
      type: 'button', class: 'primary', 'aria-label': `Go to ${point.name}`,
      onclick: () => attemptOn(state.chosen, (robot) => api.post(paths.robot.goToPoint(robot, point.name), { kind: 'movj' }),
        `Moving to ${point.name}.`),
    }, 'Go'),
    el('button', { type: 'button', 'aria-label': `Rename ${point.name}`, onclick: edit }, 'Rename'),
    confirmable('Delete', { 'aria-label': `Delete ${point.name}` }, () => attempt(async () => {
      await api.del(paths.point(point.name));
      await loadPoints();
    }, `${point.name} deleted.`)));
  const edit = () => {
    const input = el('input', { type: 'text', value: point.name, 'aria-label': `New name for ${point.name}` });
    const save = () => attempt(async () => {
      await api.post(paths.renamePoint(point.name), { name: input.value.trim() });
      await loadPoints();
    });
    // Esc cancels the new name; preventDefault tells the emergency stop's key that it did (estop.js).
    input.addEventListener('keydown', (e) => { if (e.key === 'Enter') save(); if (e.key === 'Escape') { e.preventDefault(); show(); } });
    li.replaceChildren(input, el('button', { type: 'button', class: 'primary', onclick: save }, 'Save name'),
      el('button', { type: 'button', onclick: show }, 'Cancel'));
    input.focus();
    input.select();
  };
  show();
  return li;
}

export function pointsPanel() {
  const list = el('ul', { class: 'points', 'aria-label': 'Taught points' });
  const name = kept('points.name', el('input', { type: 'text', 'aria-label': 'Name of the next point', placeholder: 'point-1' }));
  const capture = el('button', {
    type: 'button', class: 'primary capture',
    onclick: () => attemptOn(state.chosen, async (robot) => {
      const p = await api.post(paths.robot.capture(robot), name.value.trim() ? { name: name.value.trim() } : {});
      setKept(name, '');
      await loadPoints();
      return p;
    }, (p) => `Captured ${p.name}.`),
  }, 'Capture point');
  const panel = el('section', { class: 'panel', 'aria-label': 'Points' },
    el('h2', {}, 'Points'),
    el('div', { class: 'row' }, capture, el('label', {}, 'Name ', name)),
    list);
  // The name a capture would take follows the arm ("above-can" over the can, "fridge-1" at
  // the fridge); the server names it, so the page asks while the panel is on screen.
  const suggest = async () => {
    if (!state.chosen || document.hidden) return;
    try {
      const s = await api.get(paths.robot.suggestedPointName(state.chosen));
      name.placeholder = s.name;
    } catch { /* the robot went away: keep the last suggestion */ }
  };
  const timer = setInterval(suggest, 1000);
  const off = onPointsChange((data) => {
    name.placeholder = data.suggested;
    suggest();
    list.replaceChildren(...(data.points.length ? data.points.map(row)
      : [el('li', { class: 'muted' }, 'No points yet: move the arm and touch Capture point.')]));
  });
  loadPoints().catch((e) => notify(e.message));
  return { panel, unmount: () => { off(); clearInterval(timer); } };
}
