// Pioneer arm tab: the Katana arm on the Pioneer (pioneer-sim), jogged like the ASIBOT.
import { choose, connectedRobots, state } from '../api.js';
import { el } from '../ui.js';
import { viewer } from '../viewer3d.js';
import { cartesianControls } from './cartesian.js';
import { jointControls } from './joint.js';

function katana() {
  return connectedRobots().find((r) => r.arm === 'katana');
}

export default {
  id: 'pioneer',
  title: 'Pioneer arm',
  mount(root) {
    let built = null;   // the controls, once a Pioneer with an arm is on the bus
    const waiting = () => root.replaceChildren(el('section', { class: 'panel' }, el('h2', {}, 'Pioneer arm'),
      el('p', {}, 'No Pioneer with an arm is connected. `asibot up` starts pioneer-sim, the Pioneer P3-AT with its Katana arm in the apartment.')));
    const build = (robot) => {
      if (state.chosen !== robot.id) choose(robot.id);
      const cart = cartesianControls();
      const left = el('div');
      root.replaceChildren(el('p', { class: 'big' }, `This page commands ${robot.id}, the Katana arm on the Pioneer.`),
        el('div', { class: 'columns' }, left,
          el('div', {}, el('section', { class: 'panel', 'aria-label': '3D view' }, viewer().root), cart.panel)));
      built = { cart, left, joints: null };
    };
    // The robots may arrive after the tab opens (a page loaded straight on #pioneer).
    const update = (robot) => {
      if (!built) {
        const k = katana();
        if (!k) return;
        build(k);
        return;
      }
      if (!built.joints && robot && robot.joints) { built.joints = jointControls(robot); built.left.replaceChildren(built.joints.panel); }
      if (built.joints) built.joints.update(robot);
      built.cart.update(robot);
    };
    waiting();
    update(null);
    return { update };
  },
};
