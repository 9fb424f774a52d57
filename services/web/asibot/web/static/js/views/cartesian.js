// Cartesian tab: jog the tool along x, y, z and its two rotations, move to (or by) a typed point
// with movj or movl as on the seed, open and close the gripper, capture points.
import { api, chosenRobot, paths, state } from '../api.js';
import { gripperButtons, jogGrid, modeAndSpeed, stopButton } from '../jog.js';
import { pointsPanel } from '../points.js';
import { attempt, el } from '../ui.js';
import { viewer } from '../viewer3d.js';

export function cartesianControls() {
  const axes = state.config.jog.point_axes;
  const rows = axes.map((a, i) => ({ label: a.name, unit: a.unit, digits: a.unit === 'm' ? 3 : 1, axis: i }));
  const jog = jogGrid('cartesian', rows, (r) => r.point);

  const inputs = rows.map((row) => el('input', {
    type: 'number', step: row.unit === 'm' ? '0.01' : '1', value: '0', 'aria-label': `${row.label} value, ${row.unit}`,
  }));
  const form = el('div', { class: 'form-grid' }, rows.map((row, i) => el('label', {}, `${row.label} (${row.unit})`, inputs[i])));
  const origin = el('select', { 'aria-label': 'Origin' },
    el('option', { value: 'absolute' }, 'Absolute (base frame)'), el('option', { value: 'relative' }, 'Relative to the tool now'));
  const kind = el('select', { 'aria-label': 'Movement' },
    el('option', { value: 'movj' }, 'movj: joints interpolated'), el('option', { value: 'movl' }, 'movl: straight line'));
  const values = () => inputs.map((x) => Number(x.value));
  const target = () => {
    const r = chosenRobot();
    if (origin.value === 'absolute' || !r || !r.point) return values();
    return values().map((v, i) => v + r.point[i]);
  };
  const showTarget = () => attempt(async () => {
    const reply = await api.post(paths.robot.inverse(state.chosen), { point: target() });
    viewer().showGhost(reply.names, reply.joints);
  });
  const fromArm = () => {
    const r = chosenRobot();
    if (r && r.point) { origin.value = 'absolute'; r.point.forEach((v, i) => { inputs[i].value = v.toFixed(i < 3 ? 3 : 1); }); }
  };
  const panel = el('section', { class: 'panel', 'aria-label': 'Cartesian jogging' },
    el('h2', {}, 'Move the tool'), modeAndSpeed(), jog.grid,
    el('div', { class: 'row' }, stopButton(), gripperButtons()),
    el('h3', {}, 'Move to a point'), form,
    el('div', { class: 'row' }, el('label', {}, 'Origin ', origin), el('label', {}, 'Movement ', kind)),
    el('div', { class: 'row' },
      el('button', {
        type: 'button', class: 'primary',
        onclick: () => attempt(() => api.post(paths.robot.move(state.chosen),
          { kind: kind.value, values: values(), relative: origin.value === 'relative' }), 'Moving.'),
      }, 'Move'),
      el('button', { type: 'button', onclick: showTarget }, 'Show target'),
      el('button', { type: 'button', onclick: fromArm }, 'Copy current point'),
      el('button', { type: 'button', onclick: () => viewer().showGhost(null) }, 'Hide target')));
  return { panel, update: jog.update };
}

export default {
  id: 'cartesian',
  title: 'Cartesian',
  mount(root) {
    const controls = cartesianControls();
    const points = pointsPanel();
    root.replaceChildren(el('div', { class: 'columns' }, controls.panel,
      el('div', {}, el('section', { class: 'panel', 'aria-label': '3D view' }, viewer().root), points.panel)));
    return { update: controls.update, unmount: points.unmount };
  },
};
