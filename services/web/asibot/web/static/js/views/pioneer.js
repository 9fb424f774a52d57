// Pioneer arm tab: the Katana arm on the Pioneer (pioneer-sim), jogged like the ASIBOT.
// Opening the tab never changes the robot the page commands: while another robot is commanded,
// the tab says which robot it is about and offers the one button that commands it.
import { chosenRobot, connectedRobots } from '../api.js';
import { offerToCommand } from '../connection.js';
import { el } from '../ui.js';
import { viewer } from '../viewer3d.js';
import { cartesianControls } from './cartesian.js';
import { jointControls } from './joint.js';

function katana() {
  return connectedRobots().find((r) => r.arm === 'katana');
}

export default {
  mount(root) {
    let built = null;   // the controls, while the page commands a Pioneer with an arm
    let shown = null;   // what the tab shows now: '' (waiting), 'offer:<id>:<commanded>' or 'controls:<id>'
    const waiting = () => root.replaceChildren(el('section', { class: 'panel' }, el('h2', {}, 'Pioneer arm'),
      el('p', {}, 'No Pioneer with an arm is connected. `asibot up` starts pioneer-sim, the Pioneer P3-AT with its Katana arm in the apartment.')));
    const build = (robot) => {
      const cart = cartesianControls('pioneer.cartesian');
      const left = el('div');
      root.replaceChildren(el('p', { class: 'big' }, `This page commands ${robot.id}, the Katana arm on the Pioneer.`),
        el('div', { class: 'columns' }, left,
          el('div', {}, el('section', { class: 'panel', 'aria-label': '3D view' }, viewer().root), cart.panel)));
      built = { cart, left, joints: null };
    };
    // The robots may arrive after the tab opens (a page loaded straight on #pioneer).
    const update = () => {
      const k = katana();
      const commanded = chosenRobot();
      const mode = !k ? '' : commanded && commanded.id === k.id ? `controls:${k.id}` : `offer:${k.id}:${commanded ? commanded.id : ''}`;
      if (mode !== shown) {
        shown = mode;
        built = null;
        if (!k) waiting();
        else if (mode.startsWith('offer:')) root.replaceChildren(offerToCommand(k, 'the Katana arm on the Pioneer', commanded));
        else build(k);
      }
      if (!built) return;
      if (!built.joints && commanded.joints) { built.joints = jointControls(commanded); built.left.replaceChildren(built.joints.panel); }
      if (built.joints) built.joints.update(commanded);
      built.cart.update(commanded);
    };
    update();
    return { update };
  },
};
