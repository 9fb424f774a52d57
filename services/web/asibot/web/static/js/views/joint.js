// Joint tab: jog each joint, move all joints to (or by) typed values, capture points. The typed
// values are kept per robot (keep.js): a tab switch or a reload does not reset them.
import { api, chosenRobot, paths, state } from '../api.js';
import { jogGrid, modeAndSpeed, stopButton } from '../jog.js';
import { kept, setKept } from '../keep.js';
import { pointsPanel } from '../points.js';
import { attemptOn, el } from '../ui.js';
import { viewer } from '../viewer3d.js';
import { robotLabel } from './cartesian.js';

export function jointControls(robot) {
  const names = robot && robot.joints ? robot.joints.names : [];
  const rows = names.map((name, i) => ({ label: `Joint ${i + 1}`, unit: 'deg', digits: 1, axis: i, name }));
  const jog = jogGrid('joint', rows, (r) => r.joints && r.joints.deg);

  const inputs = rows.map((row, i) => kept(`joint.${robot.id}.${i}`,
    el('input', { type: 'number', step: '1', value: '0', 'aria-label': `${row.label} value, deg` })));
  const form = el('div', { class: 'form-grid' }, rows.map((row, i) => el('label', {}, `${row.label} (deg)`, inputs[i])));
  const values = () => inputs.map((x) => Number(x.value));
  const ghost = () => viewer().showGhost(names, values());
  inputs.forEach((x) => x.addEventListener('input', ghost));
  const move = (relative) => attemptOn(state.chosen, (id) => api.post(paths.robot.move(id),
    { kind: 'movj', values: values(), joints: true, relative }), relative ? 'Moving by the offsets.' : 'Moving to the joint values.');
  const fromArm = el('button', {
    type: 'button', onclick: () => {
      const r = chosenRobot();
      if (r && r.joints) r.joints.deg.forEach((v, i) => { if (inputs[i]) setKept(inputs[i], v.toFixed(1)); });
      ghost();
    },
  }, 'Copy current joints');

  const label = robotLabel();
  const panel = el('section', { class: 'panel', 'aria-label': 'Joint jogging' },
    el('h2', {}, 'Move joints', label.label), modeAndSpeed(), jog.grid,
    el('div', { class: 'row' }, stopButton(),
      el('button', { type: 'button', onclick: () => attemptOn(state.chosen, (id) => api.post(paths.robot.home(id), {}), 'Going home.') }, 'Home')),
    el('h3', {}, 'Move all joints'), form,
    el('div', { class: 'row' },
      el('button', { type: 'button', class: 'primary', onclick: () => move(false) }, 'Move to these joints'),
      el('button', { type: 'button', onclick: () => move(true) }, 'Move by these offsets'),
      fromArm,
      el('button', { type: 'button', onclick: () => viewer().showGhost(null) }, 'Hide target')));
  return { panel, update: (r) => { jog.update(r); label.update(r); } };
}

export default {
  mount(root) {
    let controls = null;
    let shownFor = null;
    const points = pointsPanel();
    const left = el('div');
    const right = el('div', {}, el('section', { class: 'panel', 'aria-label': '3D view' }, viewer().root), points.panel);
    root.replaceChildren(el('div', { class: 'columns' }, left, right));
    const update = (robot) => {
      const key = robot ? `${robot.id}:${robot.joints ? robot.joints.names.length : 0}` : '';
      if (key !== shownFor) {
        shownFor = key;
        controls = jointControls(robot);
        left.replaceChildren(controls.panel);
      }
      controls.update(robot);
    };
    return { update, unmount: points.unmount };
  },
};
