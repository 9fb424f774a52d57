// Pioneer arm tab: the Katana arm on the Pioneer (pioneer-sim), jogged like the ASIBOT.
import { choose, state } from '../api.js';
import { el } from '../ui.js';
import { viewer } from '../viewer3d.js';
import { cartesianControls } from './cartesian.js';
import { jointControls } from './joint.js';

export default {
  id: 'pioneer',
  title: 'Pioneer arm',
  mount(root) {
    const katana = [...state.robots.values()].find((r) => r.arm === 'katana' && (r.driver || r.controller));
    if (!katana) {
      root.replaceChildren(el('section', { class: 'panel' }, el('h2', {}, 'Pioneer arm'),
        el('p', {}, 'No Pioneer with an arm is connected. `asibot up` starts pioneer-sim, the Pioneer P3-AT with its Katana arm in the apartment.')));
      return {};
    }
    if (state.chosen !== katana.id) choose(katana.id);
    const cart = cartesianControls();
    let joints = null;
    const left = el('div');
    root.replaceChildren(el('p', { class: 'big' }, `This page commands ${katana.id}, the Katana arm on the Pioneer.`),
      el('div', { class: 'columns' }, left,
        el('div', {}, el('section', { class: 'panel', 'aria-label': '3D view' }, viewer().root), cart.panel)));
    const update = (robot) => {
      if (!joints && robot && robot.joints) { joints = jointControls(robot); left.replaceChildren(joints.panel); }
      if (joints) joints.update(robot);
      cart.update(robot);
    };
    return { update };
  },
};
