// A camera's live picture as a control: touch or click a spot of it, or, with a keyboard or a
// switch, "Pick a spot": a cross-hair moved by arrow buttons (or the arrow keys) and selected
// with "Select this spot", so touching is never the only way (WCAG 2.5.7, 2.1.1). Whoever holds
// the picture hears the spot in the image's own pixels (u across, v down), as the server's
// touch takes them. "Enlarge" lets the picture fill the panel it sits in, and back.
import { paths } from './api.js';
import { el } from './ui.js';

// The cross-hair moves this fraction of the picture's width a press.
const NUDGE = 1 / 40;

export class CameraPicture {
  // onSpot(u, v): a spot was chosen; onEnlarge(on): the picture asks to fill the panel (or not).
  constructor({ onSpot, onEnlarge = () => {} }) {
    this.onSpot = onSpot;
    this.onEnlarge = onEnlarge;
    this.robot = this.name = null;
    this.size = { width: 0, height: 0 };
    this.spot = null;              // [u, v] of the cross-hair, image pixels
    this.img = el('img', { class: 'camera-picture', alt: 'The camera\'s live picture: touch a spot to choose it' });
    this.img.addEventListener('click', (e) => this.clicked(e));
    this.img.addEventListener('load', () => this.place());
    this.cross = el('div', { class: 'cross-hair', hidden: true, 'aria-hidden': 'true' });
    this.frame = el('div', { class: 'camera-frame' }, this.img, this.cross);
    this.frame.addEventListener('keydown', (e) => this.key(e));
    this.enlargeButton = el('button', { type: 'button', 'aria-pressed': 'false', onclick: () => this.enlarge(!this.large) }, 'Enlarge');
    this.pickButton = el('button', { type: 'button', 'aria-pressed': 'false', onclick: () => this.picking(!this.pick) }, 'Pick a spot');
    const arrow = (label, du, dv, text) => el('button', { type: 'button', 'aria-label': label, onclick: () => this.nudge(du, dv) }, text);
    this.arrows = el('div', { class: 'row pick-arrows', role: 'group', 'aria-label': 'Move the cross-hair', hidden: true },
      arrow('Cross-hair left', -1, 0, '←'), arrow('Cross-hair up', 0, -1, '↑'),
      arrow('Cross-hair down', 0, 1, '↓'), arrow('Cross-hair right', 1, 0, '→'),
      el('button', { type: 'button', class: 'primary', onclick: () => this.select() }, 'Select this spot'));
    this.root = el('div', { class: 'camera-box' }, this.frame,
      el('div', { class: 'row', role: 'group', 'aria-label': 'Camera picture controls' }, this.enlargeButton, this.pickButton),
      this.arrows);
    this.large = false;
    this.pick = false;
    new ResizeObserver(() => this.place()).observe(this.frame);
  }

  // Show camera `name` of `robot` ({width, height} of its images); null shows nothing.
  show(robot, camera) {
    const key = camera ? `${robot}/${camera.name}` : null;
    if (key === (this.robot && `${this.robot}/${this.name}`)) return;
    this.robot = camera ? robot : null;
    this.name = camera ? camera.name : null;
    this.size = camera ? { width: camera.width, height: camera.height } : { width: 0, height: 0 };
    this.spot = null;
    this.cross.hidden = true;
    if (camera) this.img.src = paths.robot.camera(robot, camera.name);
    else this.img.removeAttribute('src');
    this.img.dataset.camera = this.name || '';
  }

  // Leaving the view drops the stream (an <img> without src closes it).
  stop() { this.img.removeAttribute('src'); this.robot = this.name = null; }

  width() { return this.img.naturalWidth || this.size.width; }
  height() { return this.img.naturalHeight || this.size.height; }

  clicked(e) {
    const r = this.img.getBoundingClientRect();
    if (!r.width || !r.height || !this.width()) return;
    const u = ((e.clientX - r.left) / r.width) * this.width() - 0.5;
    const v = ((e.clientY - r.top) / r.height) * this.height() - 0.5;
    this.mark(u, v);
    this.picking(false);
    this.onSpot(this.spot[0], this.spot[1]);
  }

  // Put the cross-hair at (u, v) image pixels, kept inside the picture.
  mark(u, v) {
    const w = this.width(), h = this.height();
    this.spot = [Math.min(Math.max(u, 0), w - 1), Math.min(Math.max(v, 0), h - 1)];
    this.cross.hidden = false;
    this.place();
  }

  place() {
    if (!this.spot || !this.width()) return;
    const r = this.img.getBoundingClientRect(), f = this.frame.getBoundingClientRect();
    this.cross.style.left = `${r.left - f.left + ((this.spot[0] + 0.5) / this.width()) * r.width}px`;
    this.cross.style.top = `${r.top - f.top + ((this.spot[1] + 0.5) / this.height()) * r.height}px`;
  }

  picking(on) {
    this.pick = on;
    this.pickButton.setAttribute('aria-pressed', String(on));
    this.arrows.hidden = !on;
    this.frame.tabIndex = on ? 0 : -1;
    if (on && !this.spot && this.width()) this.mark(this.width() / 2, this.height() / 2);
  }

  nudge(du, dv) {
    if (!this.spot) this.mark(this.width() / 2, this.height() / 2);
    const step = Math.max(1, Math.round(this.width() * NUDGE));
    this.mark(this.spot[0] + du * step, this.spot[1] + dv * step);
  }

  select() {
    if (!this.spot) return;
    this.picking(false);
    this.onSpot(this.spot[0], this.spot[1]);
  }

  key(e) {
    if (!this.pick) return;
    const moves = { ArrowLeft: [-1, 0], ArrowRight: [1, 0], ArrowUp: [0, -1], ArrowDown: [0, 1] };
    if (moves[e.key]) { e.preventDefault(); this.nudge(...moves[e.key]); }
    else if (e.key === 'Enter' || e.key === ' ') { e.preventDefault(); this.select(); }
  }

  enlarge(on) {
    this.large = on;
    this.enlargeButton.setAttribute('aria-pressed', String(on));
    this.enlargeButton.textContent = on ? 'Smaller' : 'Enlarge';
    this.root.classList.toggle('large', on);
    // As wide as the panel, but never taller than 3/4 of the screen (the picture keeps its shape).
    const aspect = this.width() && this.height() ? this.width() / this.height() : 4 / 3;
    this.img.style.width = on ? `min(100%, ${(75 * aspect).toFixed(2)}vh)` : '';
    this.onEnlarge(on);
    requestAnimationFrame(() => this.place());
  }
}
