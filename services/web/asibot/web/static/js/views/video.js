// Video tab: the commanded robot's cameras (simulated or real: any camera on the bus), live.
import { api, paths } from '../api.js';
import { el, notify } from '../ui.js';

export default {
  mount(root) {
    const grid = el('div', { class: 'video' });
    const heading = el('h2', {}, 'Cameras');
    let shown = null;
    const load = async (robot) => {
      shown = robot ? robot.id : null;
      if (!robot) { grid.replaceChildren(el('p', { class: 'muted' }, 'No robot commanded: press Command beside one in the Connection Manager at the top.')); return; }
      heading.textContent = `Cameras of ${robot.id}`;
      const { cameras } = await api.get(paths.robot.cameras(robot.id));
      grid.replaceChildren(...(cameras.length ? cameras.map((name) => el('figure', {},
        el('img', { src: paths.robot.camera(robot.id, name), alt: `Live image of the ${name} camera` }),
        el('figcaption', {}, name))) : [el('p', { class: 'muted' }, `${robot.id} has no camera sending images.`)]));
    };
    root.replaceChildren(el('section', { class: 'panel', 'aria-label': 'Video' }, heading, grid));
    const update = (robot) => { if ((robot ? robot.id : null) !== shown) load(robot).catch((e) => notify(e.message)); };
    // Leaving the tab drops the <img> elements, which closes their streams.
    return { update, unmount: () => grid.replaceChildren() };
  },
};
