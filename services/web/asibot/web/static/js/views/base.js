// Base tab: a mobile robot's map with where it is (and how sure: its particles), what its scan
// sees and the way it plans; tap the map to send it there, or choose a named place; drive it
// with the thesis's primitives as large buttons; keep its places. It drives the robot the page
// commands; while that one has no base, it says which robot it is about and offers to command it
// (opening the tab never changes the commanded robot).
import { api, chosenRobot, connectedRobots, onChange, paths, state } from '../api.js';
import { kept, setKept } from '../keep.js';
import { offerToCommand } from '../connection.js';
import { attemptOn, confirmable, el, notify } from '../ui.js';

const COLOURS = { free: [255, 255, 255], occupied: [19, 32, 43], unknown: [201, 209, 216] };
const PX_PER_CELL = 3;

function bases() {
  return connectedRobots().filter((r) => r.has_base);
}

// The map: its grid drawn once into an image, the live layers on top at every update.
class MapView {
  constructor(robotId, onTap) {
    this.robotId = robotId;
    this.canvas = el('canvas', {
      class: 'map', role: 'img',
      'aria-label': 'Map of the robot\'s home: the robot in blue, the planned way as a blue line, what it sees in red. Tap a free spot to send it there.',
    });
    this.canvas.addEventListener('click', (e) => {
      if (!this.grid) return;
      const r = this.canvas.getBoundingClientRect();
      const cx = (e.clientX - r.left) * (this.canvas.width / r.width);
      const cy = (e.clientY - r.top) * (this.canvas.height / r.height);
      onTap(this.toMap(cx, cy));
    });
    this.live = null;
    this.places = [];
    this.frame = 0;
  }

  async load() {
    const g = await api.get(paths.base.map(this.robotId));
    const cells = Uint8Array.from(atob(g.cells), (c) => c.charCodeAt(0));
    const image = new ImageData(g.width, g.height);
    for (let row = 0; row < g.height; row += 1) {
      for (let col = 0; col < g.width; col += 1) {
        const v = (cells[row * g.width + col] << 24) >> 24;   // int8
        const c = v < 0 ? COLOURS.unknown : v >= 65 ? COLOURS.occupied : COLOURS.free;
        const i = ((g.height - 1 - row) * g.width + col) * 4;   // row 0 is the bottom of the map
        image.data.set([...c, 255], i);
      }
    }
    this.background = el('canvas', { width: g.width, height: g.height });
    this.background.getContext('2d').putImageData(image, 0, 0);
    this.grid = g;
    this.stamp = g.stamp;
    this.canvas.width = g.width * PX_PER_CELL;
    this.canvas.height = g.height * PX_PER_CELL;
    this.draw();
  }

  // map metres <-> canvas pixels
  toPx(x, y) {
    const g = this.grid;
    return [(x - g.origin[0]) / g.resolution * PX_PER_CELL,
      this.canvas.height - (y - g.origin[1]) / g.resolution * PX_PER_CELL];
  }

  toMap(px, py) {
    const g = this.grid;
    return { x: g.origin[0] + px / PX_PER_CELL * g.resolution, y: g.origin[1] + (this.canvas.height - py) / PX_PER_CELL * g.resolution };
  }

  update(nav, places) {
    this.live = nav;
    // nav changed its map (one being built while mapping, or a new one in use): fetch it again
    if (nav && nav.map && this.grid && nav.map !== this.stamp && !this.loading) {
      this.loading = true;
      this.load().catch((e) => notify(e.message)).finally(() => { this.loading = false; });
    }
    if (places) this.places = places;
    if (!this.frame) this.frame = requestAnimationFrame(() => { this.frame = 0; this.draw(); });
  }

  draw() {
    if (!this.grid) return;
    const ctx = this.canvas.getContext('2d');
    const scale = PX_PER_CELL / this.grid.resolution;   // px per m
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.background, 0, 0, this.canvas.width, this.canvas.height);
    ctx.font = '600 14px system-ui, sans-serif';
    for (const p of this.places) {
      const [px, py] = this.toPx(p.pose[0], p.pose[1]);
      ctx.fillStyle = '#1b7a3a';
      ctx.beginPath(); ctx.arc(px, py, 5, 0, 2 * Math.PI); ctx.fill();
      ctx.fillStyle = '#13202b';
      ctx.fillText(p.name, px + 8, py - 6);
    }
    const nav = this.live;
    if (!nav) return;
    ctx.fillStyle = 'rgba(11, 92, 173, 0.35)';
    for (const [x, y] of nav.particles) { const [px, py] = this.toPx(x, y); ctx.fillRect(px - 1, py - 1, 3, 3); }
    if (nav.path.length) {
      ctx.strokeStyle = '#0b5cad'; ctx.lineWidth = 3; ctx.beginPath();
      nav.path.forEach(([x, y], i) => { const [px, py] = this.toPx(x, y); if (i) ctx.lineTo(px, py); else ctx.moveTo(px, py); });
      ctx.stroke();
    }
    const goal = nav.status && nav.status.state === 'active' && nav.status.goal.length ? nav.status.goal : null;
    if (goal) {
      const [gx, gy] = this.toPx(goal[0], goal[1]);
      ctx.strokeStyle = '#0b5cad'; ctx.lineWidth = 3;
      ctx.beginPath(); ctx.arc(gx, gy, 9, 0, 2 * Math.PI); ctx.stroke();
    }
    ctx.fillStyle = '#b3141b';
    for (const [x, y] of nav.scan) { const [px, py] = this.toPx(x, y); ctx.fillRect(px - 1.5, py - 1.5, 3, 3); }
    if (nav.pose) {
      const [px, py] = this.toPx(nav.pose.x, nav.pose.y);
      const a = -nav.pose.theta_deg * Math.PI / 180;   // the canvas' y goes down
      ctx.save(); ctx.translate(px, py); ctx.rotate(a);
      const half = 0.26 * scale;                       // the P3-AT is about 0.5 m square
      ctx.fillStyle = nav.pose.localised ? '#0b5cad' : '#8a5a00';
      ctx.fillRect(-half, -half * 0.95, 2 * half, 1.9 * half);
      ctx.fillStyle = '#ffffff';
      ctx.beginPath(); ctx.moveTo(half * 0.9, 0); ctx.lineTo(-half * 0.3, half * 0.55); ctx.lineTo(-half * 0.3, -half * 0.55); ctx.fill();
      ctx.restore();
    }
  }
}

function statusText(robot) {
  const nav = robot && robot.nav;
  if (!nav || !nav.status) return 'Waiting for the navigation service…';
  const s = nav.status;
  let text = s.text ? s.text[0].toUpperCase() + s.text.slice(1) : s.state;
  if (s.state === 'active' && s.eta) text += `, about ${Math.ceil(s.eta)} s`;
  if (!s.localised) text += '. I am not sure where I am.';
  if (s.mapping) text += ` (${s.mapping[0].toUpperCase()}${s.mapping.slice(1)})`;
  return text;
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
  const panel = el('section', { class: 'panel', 'aria-label': 'Drive' }, el('h2', {}, 'Drive'),
    el('div', { class: 'drives', role: 'group', 'aria-label': 'Driving primitives' }, ...state.config.base.drives.flat().map(button)),
    el('div', { class: 'row' }, keepGoing, ...changes), levels);
  return { panel, levels };
}

export default {
  id: 'base',
  title: 'Base',
  mount(root) {
    let built = null;
    const waiting = () => root.replaceChildren(el('section', { class: 'panel' }, el('h2', {}, 'Base'),
      el('p', {}, 'No mobile robot is connected. `asibot up` starts pioneer-sim, the Pioneer P3-AT in the apartment.')));
    const build = (robot) => {
      const map = new MapView(robot.id, (p) => attemptOn(robot.id, (id) => api.post(paths.base.goto(id), { x: p.x, y: p.y }),
        `On the way to (${p.x.toFixed(1)}, ${p.y.toFixed(1)}).`));
      const status = el('p', { class: 'big nav-status', role: 'status', 'aria-live': 'polite' });
      const cancel = el('button', { type: 'button', class: 'danger', onclick: () => attemptOn(robot.id, (id) => api.post(paths.base.cancel(id)), 'Canceled.') }, 'Cancel the trip');
      const events = el('ul', { class: 'events', 'aria-label': 'What the robot said' });
      const drive = drivePanel(robot.id);
      const places = placesPanel(robot.id, (list) => map.update(map.live, list));
      root.replaceChildren(el('p', { class: 'big' }, `This page drives ${robot.id}.`),
        el('div', { class: 'columns' },
          el('div', {},
            el('section', { class: 'panel', 'aria-label': 'Map' }, el('h2', {}, 'Map'), el('div', { class: 'map-box' }, map.canvas),
              status, el('div', { class: 'row' }, cancel)),
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
