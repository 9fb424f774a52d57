// Cartesian tab: jog the tool along x, y, z and its two rotations, move to (or by) a typed point
// with movj or movl as on the seed, open and close the gripper, capture points. The typed point
// is kept (keep.js) under `keep`: a tab switch or a reload does not reset it.
import { api, chosenRobot, paths, state } from '../api.js';
import { gripperButtons, jogGrid, modeAndSpeed, stopButton } from '../jog.js';
import { kept, setKept } from '../keep.js';
import { pointsPanel } from '../points.js';
import { attemptOn, el } from '../ui.js';
import { viewer } from '../viewer3d.js';

// The robot a panel commands, in its heading: " of asibot-sim".
export function robotLabel() {
  const label = el('span', { class: 'robot-label' });
  return { label, update: (robot) => { label.textContent = robot ? ` of ${robot.id}` : ''; } };
}

export function cartesianControls(keep = 'cartesian') {
  const axes = state.config.jog.point_axes;
  const rows = axes.map((a, i) => ({ label: a.name, unit: a.unit, digits: a.unit === 'm' ? 3 : 1, axis: i }));
  const jog = jogGrid('cartesian', rows, (r) => r.point);

  const inputs = rows.map((row, i) => kept(`${keep}.${i}`, el('input', {
    type: 'number', step: row.unit === 'm' ? '0.01' : '1', value: '0', 'aria-label': `${row.label} value, ${row.unit}`,
  })));
  const form = el('div', { class: 'form-grid' }, rows.map((row, i) => el('label', {}, `${row.label} (${row.unit})`, inputs[i])));
  const origin = kept(`${keep}.origin`, el('select', { 'aria-label': 'Origin' },
    el('option', { value: 'absolute' }, 'Absolute (base frame)'), el('option', { value: 'relative' }, 'Relative to the tool now')));
  const kind = kept(`${keep}.movement`, el('select', { 'aria-label': 'Movement' },
    el('option', { value: 'movj' }, 'movj: joints interpolated'), el('option', { value: 'movl' }, 'movl: straight line')));
  const values = () => inputs.map((x) => Number(x.value));
  const target = () => {
    const r = chosenRobot();
    if (origin.value === 'absolute' || !r || !r.point) return values();
    return values().map((v, i) => v + r.point[i]);
  };
  const showTarget = () => attemptOn(state.chosen, async (robot) => {
    const reply = await api.post(paths.robot.inverse(robot), { point: target() });
    viewer().showGhost(reply.names, reply.joints);
  });
  const fromArm = () => {
    const r = chosenRobot();
    if (r && r.point) { setKept(origin, 'absolute'); r.point.forEach((v, i) => { setKept(inputs[i], v.toFixed(i < 3 ? 3 : 1)); }); }
  };
  const robot = robotLabel();
  const panel = el('section', { class: 'panel', 'aria-label': 'Cartesian jogging' },
    el('h2', {}, 'Move the tool', robot.label), modeAndSpeed(), jog.grid,
    el('div', { class: 'row' }, stopButton(), gripperButtons()),
    el('h3', {}, 'Move to a point'), form,
    el('div', { class: 'row' }, el('label', {}, 'Origin ', origin), el('label', {}, 'Movement ', kind)),
    el('div', { class: 'row' },
      el('button', {
        type: 'button', class: 'primary',
        onclick: () => attemptOn(state.chosen, (id) => api.post(paths.robot.move(id),
          { kind: kind.value, values: values(), relative: origin.value === 'relative' }), 'Moving.'),
      }, 'Move'),
      el('button', { type: 'button', onclick: showTarget }, 'Show target'),
      el('button', { type: 'button', onclick: fromArm }, 'Copy current point'),
      el('button', { type: 'button', onclick: () => viewer().showGhost(null) }, 'Hide target')));
  return { panel, update: (r) => { jog.update(r); robot.update(r); } };
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
