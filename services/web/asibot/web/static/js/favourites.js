// Home's "Your tasks and places": the person's tasks and places as big tiles, in the carer's
// order and then most used first (the server ranks them: api_favourites.py), and under them what
// the last one is doing, in words and in pictures: the robot's camera for a task, the map for a
// trip, each enlargeable, with the one button that stops it. Switch scanning in its Home mode
// (scanning.js) offers this panel alone, one level deep, after the Emergency stop.
import { api, onChange, onMessage, paths, state } from './api.js';
import { MapView, statusText } from './map.js';
import { attempt, attemptOn, el, notify } from './ui.js';

function taskTile(item, launch) {
  return el('button', {
    type: 'button', class: 'task-button favourite', 'aria-label': `Launch ${item.name}`,
    dataset: { key: item.key }, onclick: () => launch(item),
  }, el('img', { src: paths.icon(item.icon), alt: '' }), item.name);
}

function placeTile(item, go, robots) {
  const name = robots > 1 ? `Go to ${item.name} (${item.robot})` : `Go to ${item.name}`;
  return el('button', {
    type: 'button', class: 'task-button favourite', 'aria-label': name, dataset: { key: item.key }, onclick: () => go(item),
  }, el('img', { src: '/static/img/place.svg', alt: '' }), name);
}

// What the last task or trip is doing: words, a picture, the button that stops it.
function nowPanel() {
  const words = el('p', { class: 'big now-words', role: 'status', 'aria-live': 'polite' });
  const picture = el('div', { class: 'now-picture' });
  const enlarge = el('button', { type: 'button', 'aria-pressed': 'false' }, 'Enlarge');
  enlarge.addEventListener('click', () => {
    const on = enlarge.getAttribute('aria-pressed') !== 'true';
    enlarge.setAttribute('aria-pressed', String(on));
    picture.classList.toggle('large', on);
  });
  const stop = el('button', { type: 'button', class: 'danger' });
  const node = el('div', { class: 'now', 'aria-label': 'What is happening', hidden: true },
    el('h3', {}, 'Now'), words, picture, el('div', { class: 'row' }, enlarge, stop));
  let showing = null;   // { kind: 'task', robot } | { kind: 'trip', robot, place, map }
  const task = (robot, name) => {
    showing = { kind: 'task', robot, name };
    node.hidden = false;
    words.textContent = `${name}: starting on ${robot}…`;
    stop.textContent = 'Stop the task';
    stop.onclick = () => attempt(() => api.post(paths.stopRun), 'Task stopped.');
    picture.replaceChildren();
    api.get(paths.robot.cameras(robot)).then(({ cameras }) => {
      if (showing.kind !== 'task' || showing.robot !== robot) return;
      picture.replaceChildren(cameras.length
        ? el('img', { class: 'now-camera', src: paths.robot.camera(robot, cameras[0]), alt: `Live picture of ${robot}'s ${cameras[0]} camera` })
        : el('p', { class: 'muted' }, `${robot} has no camera sending pictures.`));
    }).catch((e) => notify(e.message));
  };
  const trip = (robot, place) => {
    // Another place chosen on the map (a touch, a switch, a dwell) sends the robot there instead.
    const map = new MapView(robot, () => {}, (place) => attempt(async () => {
      await api.post(paths.base.goto(robot), { place: place.name });
      trip(robot, place.name);
    }));
    map.canvas.setAttribute('aria-label', `Map of ${robot}'s home: the robot in blue, the way it goes as a blue line.`);
    showing = { kind: 'trip', robot, place, map };
    node.hidden = false;
    words.textContent = `On the way to ${place}…`;
    stop.textContent = 'Cancel the trip';
    stop.onclick = () => attemptOn(robot, (id) => api.post(paths.base.cancel(id)), 'Trip canceled.');
    picture.replaceChildren(el('div', { class: 'map-box' }, map.node));
    map.load().then(() => api.get(paths.base.places(robot))).then(({ places }) => map.update(state.robots.get(robot)?.nav, places))
      .catch((e) => notify(e.message));
  };
  // A task's end, as the runner tells every page.
  const run = (s) => {
    if (!showing || showing.kind !== 'task') return;
    if (s.running) words.textContent = `${s.program} is running on ${s.robot}.`;
    else if (s.last && s.last.program === showing.name) {
      words.textContent = s.last.error ? `${s.last.program} did not finish: ${s.last.error}` : `${s.last.program}: ${s.last.reason}.`;
    }
  };
  const robotChanged = () => {
    if (!showing || showing.kind !== 'trip') return;
    const robot = state.robots.get(showing.robot);
    showing.map.update(robot && robot.nav);
    words.textContent = statusText(robot);
  };
  const stopPictures = () => picture.replaceChildren();   // an <img> without a page closes its stream
  return { node, task, trip, run, robotChanged, stopPictures };
}

export function favouritesPanel() {
  const tiles = el('div', { class: 'launcher favourites', role: 'group', 'aria-label': 'Your tasks and places', dataset: { scan: 'rows' } });
  const notes = el('div', { class: 'muted' });
  const now = nowPanel();
  // No message on success: "Now" says it, beside the tiles, and nothing on the page moves.
  const launch = (item) => attemptOn(item.robot || state.chosen, async (robot) => {   // its own robot first
    const status = await api.post(paths.launchTask(item.name), { robot });
    now.task(robot, item.name);
    now.run(status);
    return status;
  });
  const go = (item) => attempt(async () => {
    const reply = await api.post(paths.base.goto(item.robot), { place: item.name });
    now.trip(item.robot, item.name);
    return reply;
  });
  const refresh = async () => {
    const { items, notes: said } = await api.get(paths.favourites);
    const robots = new Set(items.filter((i) => i.kind === 'place').map((i) => i.robot)).size;
    tiles.replaceChildren(...(items.length
      ? items.map((i) => (i.kind === 'task' ? taskTile(i, launch) : placeTile(i, go, robots)))
      : [el('p', { class: 'muted' }, 'No tasks or places yet: the Task Creator wizard below makes a task; the Base page keeps places.')]));
    notes.replaceChildren(...said.map((n) => el('p', {}, n)));
  };
  const node = el('section', { id: 'for-me', class: 'panel for-me', 'aria-label': 'Your tasks and places' },
    el('h2', {}, 'Your tasks and places'), el('div', { class: 'for-me-body' }, el('div', {}, tiles, notes), now.node));
  const offMessages = onMessage((msg) => {
    if (msg.type === 'tasks') refresh().catch((e) => notify(e.message));
    if (msg.type === 'run') now.run(msg.status);
  });
  const offChange = onChange(() => now.robotChanged());
  refresh().catch((e) => notify(e.message));
  return { node, unmount: () => { offMessages(); offChange(); now.stopPictures(); } };
}
