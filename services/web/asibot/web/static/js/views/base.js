// Base tab: a mobile robot's map with where it is (and how sure: its particles), what its scan
// sees and the way it plans; tap the map to send it there, or choose a named place; drive it
// with the thesis's primitives as large buttons; keep its places. It drives the robot the page
// commands; while that one has no base, it says which robot it is about and offers to command it
// (opening the tab never changes the commanded robot).
import { api, chosenRobot, connectedRobots, onChange, paths, state } from '../api.js';
import { kept, setKept } from '../keep.js';
import { offerToCommand } from '../connection.js';
import { attemptOn, confirmable, el, notify } from '../ui.js';
import { MapView, statusText } from '../map.js';

function bases() {
  return connectedRobots().filter((r) => r.has_base);
}

function placesPanel(robotId, onPlaces) {
  const list = el('ul', { class: 'points', 'aria-label': 'Places' });
  const name = kept(`base.${robotId}.place`, el('input', { type: 'text', 'aria-label': 'Name of the new place', placeholder: 'sofa' }));
  const load = async () => {
    const { places } = await api.get(paths.base.places(robotId));
    onPlaces(places);
    list.replaceChildren(...places.map((p) => row(p)));
  };
  const row = (p) => {
    const li = el('li', { dataset: { place: p.name } });
    const show = () => li.replaceChildren(
      el('span', { class: 'pname' }, p.name),
      el('button', {
        type: 'button', class: 'primary', 'aria-label': `Go to ${p.name}`,
        onclick: () => attemptOn(robotId, (id) => api.post(paths.base.goto(id), { place: p.name }), `On the way to ${p.name}.`),
      }, 'Go'),
      el('button', { type: 'button', 'aria-label': `Rename ${p.name}`, onclick: edit }, 'Rename'),
      confirmable('Remove', { 'aria-label': `Remove ${p.name}` }, () => attemptOn(robotId, async () => {
        await api.del(paths.base.place(robotId, p.name));
        await load();
      }, `${p.name} removed.`)));
    const edit = () => {
      const input = el('input', { type: 'text', value: p.name, 'aria-label': `New name for ${p.name}` });
      const save = () => attemptOn(robotId, async () => {
        await api.post(paths.base.renamePlace(robotId, p.name), { new_name: input.value.trim() });
        await load();
      });
      // Esc cancels the new name; preventDefault tells the emergency stop's key that it did (estop.js).
      input.addEventListener('keydown', (e) => { if (e.key === 'Enter') save(); if (e.key === 'Escape') { e.preventDefault(); show(); } });
      li.replaceChildren(input, el('button', { type: 'button', class: 'primary', onclick: save }, 'Save name'),
        el('button', { type: 'button', onclick: show }, 'Cancel'));
      input.focus();
    };
    show();
    return li;
  };
  const save = el('button', {
    type: 'button', class: 'primary',
    onclick: () => attemptOn(robotId, async () => {
      const saved = await api.post(paths.base.places(robotId), { name: name.value.trim() });
      setKept(name, '');
      await load();
      return saved;
    }, (r) => `Saved ${r.name} where the robot stands.`),
  }, 'Save this place');
  const panel = el('section', { class: 'panel', 'aria-label': 'Places' }, el('h2', {}, 'Places'),
    el('div', { class: 'row' }, el('label', {}, 'Name ', name), save), list);
  load().catch((e) => notify(e.message));
  return panel;
}

function drivePanel(robotId) {
  const keepGoing = el('button', { type: 'button', 'aria-pressed': 'false' }, 'Keep going until Stop');
  keepGoing.addEventListener('click', () => keepGoing.setAttribute('aria-pressed', String(keepGoing.getAttribute('aria-pressed') !== 'true')));
  const levels = el('p', { class: 'readout', role: 'status' });
  const button = (name) => el('button', {
    type: 'button', class: name === 'stop' ? 'drive drive-stop' : 'drive', dataset: { drive: name },
    onclick: () => attemptOn(robotId, (id) => api.post(paths.base.drive(id), { name, continuous: name !== 'stop' && keepGoing.getAttribute('aria-pressed') === 'true' })),
  }, name[0].toUpperCase() + name.slice(1));
  const changes = state.config.base.changes.map((change) => el('button', {
    type: 'button', onclick: () => attemptOn(robotId, async () => {
      const r = await api.post(paths.base.settings(robotId), { change });
      levels.textContent = r.text[0].toUpperCase() + r.text.slice(1);
    }),
  }, change[0].toUpperCase() + change.slice(1)));
  // A press starts a motion that runs on its own: the panel says so, and rings the button that
  // started it, until the robot stops (nav's status names the running primitive first).
  const moving = el('p', { class: 'moving', role: 'status' });
  const drives = state.config.base.drives.flat().map(button);
  const showMotion = (status) => {
    const running = status && status.driving ? status.driving.split(',')[0] : '';
    moving.textContent = running ? `Moving: ${status.driving}. Stop ends it.` : 'Not moving.';
    moving.classList.toggle('now', Boolean(running));
    for (const b of drives) b.classList.toggle('running', b.dataset.drive === running);
  };
  showMotion(null);
  const panel = el('section', { class: 'panel', 'aria-label': 'Drive' }, el('h2', {}, 'Drive'),
    el('div', { class: 'drives', role: 'group', 'aria-label': 'Driving primitives' }, ...drives), moving,
    el('div', { class: 'row' }, keepGoing, ...changes), levels);
  return { panel, levels, showMotion };
}

export default {
  mount(root) {
    let built = null;
    const waiting = () => root.replaceChildren(el('section', { class: 'panel' }, el('h2', {}, 'Base'),
      el('p', {}, 'No mobile robot is connected. `asibot up` starts pioneer-sim, the Pioneer P3-AT in the apartment.')));
    const build = (robot) => {
      const map = new MapView(robot.id, (p) => attemptOn(robot.id, (id) => api.post(paths.base.goto(id), { x: p.x, y: p.y }),
        `On the way to (${p.x.toFixed(1)}, ${p.y.toFixed(1)}).`),
      (place) => attemptOn(robot.id, (id) => api.post(paths.base.goto(id), { place: place.name }), `On the way to ${place.name}.`));
      const status = el('p', { class: 'big nav-status', role: 'status', 'aria-live': 'polite' });
      const cancel = el('button', { type: 'button', class: 'danger', onclick: () => attemptOn(robot.id, (id) => api.post(paths.base.cancel(id)), 'Canceled.') }, 'Cancel the trip');
      // After a restart or being carried, the robot says it lost track of where it is: this
      // button has it turn in place until it knows again.
      const find = el('button', { type: 'button', class: 'find-me', onclick: () => attemptOn(robot.id, (id) => api.post(paths.base.localize(id)), 'Turning in place to find where I am.') }, 'Find where I am');
      const events = el('ul', { class: 'events', 'aria-label': 'What the robot said' });
      const drive = drivePanel(robot.id);
      const places = placesPanel(robot.id, (list) => map.update(map.live, list));
      root.replaceChildren(el('p', { class: 'big' }, `This page drives ${robot.id}.`),
        el('div', { class: 'columns' },
          el('div', {},
            el('section', { class: 'panel', 'aria-label': 'Map' }, el('h2', {}, 'Map'), el('div', { class: 'map-box' }, map.node),
              status, el('div', { class: 'row' }, cancel, find)),
            el('section', { class: 'panel', 'aria-label': 'Messages' }, el('h2', {}, 'Messages'), events)),
          el('div', {}, drive.panel, places)));
      map.load().catch((e) => notify(e.message));
      let shownEvents = '';
      built = {
        id: robot.id,
        update: (r) => {
          map.update(r.nav);
          status.textContent = statusText(r);
          const s = r.nav && r.nav.status;
          drive.showMotion(s);
          if (s && !drive.levels.textContent) drive.levels.textContent = `Speed ${s.speed} of 5, width ${s.width} of 5.`;
          const recent = r.events.slice(-6).reverse();
          const key = recent.map((e) => e.time).join();
          if (key !== shownEvents) {
            shownEvents = key;
            events.replaceChildren(...recent.map((e) => el('li', { class: `event ${e.level}` }, e.text)));
          }
        },
      };
      built.update(robot);
    };
    let offered = null;   // 'robot:commanded' while the tab offers to command a robot with a base
    const update = () => {
      const commanded = chosenRobot();
      const robot = commanded && commanded.has_base && bases().includes(commanded) ? commanded : null;
      if (!robot) {
        const other = bases()[0];
        const key = other ? `${other.id}:${commanded ? commanded.id : ''}` : '';
        if (built || key !== offered) {
          built = null;
          offered = key;
          if (other) root.replaceChildren(offerToCommand(other, 'a mobile robot: its map, its places and its driving buttons', commanded));
          else waiting();
        }
        return;
      }
      offered = null;
      if (!built || built.id !== robot.id) build(robot);
      else built.update(robot);
    };
    waiting();
    update();
    const off = onChange(update);
    return { unmount: off };
  },
};
