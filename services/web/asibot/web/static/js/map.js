// A mobile robot's map, drawn on a canvas: the map's grid once, then the live layers (where the
// robot is and how sure, its particles, what its scan sees, the way it plans, the goal) and the
// named places. Tapping the map hands the caller a point of it (m). Each named place is also a
// button on the map (`onPlace`), so a keyboard, a switch or a dwell chooses a place on the map as
// a touch does. The Base page and Home's trips show it (`node`); statusText says the nav
// service's state in words.
import { api, paths } from './api.js';
import { el, notify } from './ui.js';

const COLOURS = { free: [255, 255, 255], occupied: [19, 32, 43], unknown: [201, 209, 216] };
const PX_PER_CELL = 3;

// The map: its grid drawn once into an image, the live layers on top at every update.
export class MapView {
  constructor(robotId, onTap, onPlace) {
    this.robotId = robotId;
    this.onPlace = onPlace;
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
    this.targets = el('div', { class: 'map-places', role: 'group', 'aria-label': 'Places on the map' });
    this.node = el('div', { class: 'map-stage' }, this.canvas, this.targets);
  }

  // The places as buttons where they are on the map (in % of it: they follow its size).
  placeButtons() {
    if (!this.grid) return;
    this.targets.replaceChildren(...this.places.map((p) => {
      const [px, py] = this.toPx(p.pose[0], p.pose[1]);
      // Above its spot (the robot standing there stays seen; below it at the top), and inside
      // the map at its edges.
      const x = px / this.canvas.width, y = py / this.canvas.height;
      const tx = x < 0.2 ? '-12px' : x > 0.8 ? 'calc(-100% + 12px)' : '-50%';
      const ty = y < 0.2 ? '6px' : 'calc(-100% - 6px)';
      return el('button', {
        type: 'button', class: 'map-place', 'aria-label': `Go to ${p.name} on the map`, dataset: { place: p.name },
        style: `left: ${(100 * x).toFixed(2)}%; top: ${(100 * y).toFixed(2)}%; transform: translate(${tx}, ${ty})`,
        onclick: () => this.onPlace(p),
      }, p.name);
    }));
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
    if (this.onPlace) this.placeButtons();
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
    if (places) { this.places = places; if (this.onPlace) this.placeButtons(); }
    if (!this.frame) this.frame = requestAnimationFrame(() => { this.frame = 0; this.draw(); });
  }

  draw() {
    if (!this.grid) return;
    const ctx = this.canvas.getContext('2d');
    const scale = PX_PER_CELL / this.grid.resolution;   // px per m
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(this.background, 0, 0, this.canvas.width, this.canvas.height);
    for (const p of this.places) {
      const [px, py] = this.toPx(p.pose[0], p.pose[1]);
      ctx.fillStyle = '#1b7a3a';
      ctx.beginPath(); ctx.arc(px, py, 5, 0, 2 * Math.PI); ctx.fill();
    }
    this.drawLive(scale);
    // The places' names last, on a white edge: the robot standing at one never hides its name
    // (or, as buttons, over the map).
    if (this.onPlace) return;
    ctx.font = '600 14px system-ui, sans-serif';
    ctx.lineWidth = 4; ctx.strokeStyle = '#ffffff'; ctx.fillStyle = '#13202b';
    for (const p of this.places) {
      const [px, py] = this.toPx(p.pose[0], p.pose[1]);
      ctx.strokeText(p.name, px + 8, py - 6);
      ctx.fillText(p.name, px + 8, py - 6);
    }
  }

  drawLive(scale) {
    const ctx = this.canvas.getContext('2d');
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

export function statusText(robot) {
  const nav = robot && robot.nav;
  if (!nav || !nav.status) return 'Waiting for the navigation service…';
  const s = nav.status;
  let text = s.text ? s.text[0].toUpperCase() + s.text.slice(1) : s.state;
  if (s.state === 'active' && s.eta) text += `, about ${Math.ceil(s.eta)} s`;
  if (!s.localised) text += '. I am not sure where I am.';
  if (s.mapping) text += ` (${s.mapping[0].toUpperCase()}${s.mapping.slice(1)})`;
  return text;
}
