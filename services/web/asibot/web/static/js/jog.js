// Jog controls shared by the Joint, Cartesian and Pioneer arm pages.
//
// Two ways to move, as on teach pendants: Step (one touch = one step, the seed's 5 deg / 0.10 m /
// 15 deg) and Hold to move (the arm moves while the button is held: the page sends a beat every
// BEAT_MS; it stops on pointer up, pointer cancel, lost capture, window blur and hidden tab, and
// if the beats stop for any other reason the controller's 200 ms watchdog stops the arm).
// With switch scanning (scanning.js) a hold cannot be held: a select starts the movement and the
// next press of the switch stops it; the stops above still apply.
import { api, chosenRobot, paths, sendLive, state } from './api.js';
import { attemptOn, el, fmt } from './ui.js';

const BEAT_MS = 80;
const prefs = {
  get mode() { return localStorage.getItem('asibot.jogmode') || 'step'; },
  set mode(v) { localStorage.setItem('asibot.jogmode', v); },
  get level() { return Number(localStorage.getItem('asibot.level') || 3); },
  set level(v) { localStorage.setItem('asibot.level', String(v)); },
};

// --- hold-to-move: one held button at a time --------------------------------------------------
let held = null;   // { timer, button, unlatch? }

function release() {
  if (!held) return;
  const was = held;
  held = null;
  clearInterval(was.timer);
  was.button.classList.remove('active');
  sendLive({ type: 'release' });
  if (was.unlatch) was.unlatch();   // tell the scanner the movement ended (it moves on)
}
window.addEventListener('blur', release);
document.addEventListener('visibilitychange', () => { if (document.hidden) release(); });
window.addEventListener('pagehide', release);

function startHold(button, beat) {
  release();
  button.classList.add('active');
  const send = () => sendLive({ type: 'hold', ...beat() });
  send();
  held = { button, timer: setInterval(send, BEAT_MS) };
}

function holdable(button, beat) {
  button.addEventListener('pointerdown', (e) => {
    if (prefs.mode !== 'hold' || e.button !== 0) return;
    e.preventDefault();
    button.setPointerCapture(e.pointerId);
    startHold(button, beat);
  });
  for (const ev of ['pointerup', 'pointercancel', 'lostpointercapture']) button.addEventListener(ev, release);
  // Keyboard and switch users: Space or Enter held down moves, let go stops.
  button.addEventListener('keydown', (e) => {
    if (prefs.mode !== 'hold' || (e.key !== ' ' && e.key !== 'Enter')) return;
    e.preventDefault();
    if (!e.repeat) startHold(button, beat);
  });
  button.addEventListener('keyup', (e) => { if (e.key === ' ' || e.key === 'Enter') release(); });
  button.addEventListener('blur', release);
  // Switch scanning's select: start, and hand the scanner the stop for the switch's next press.
  button.addEventListener('scan:select', (e) => {
    if (prefs.mode !== 'hold') return;
    e.preventDefault();
    startHold(button, beat);
    held.unlatch = e.detail.latch(release);
  });
}

// --- the controls ---------------------------------------------------------------------------
export function modeAndSpeed(onModeChange = () => {}) {
  const modeButtons = ['step', 'hold'].map((mode) => el('button', {
    type: 'button', 'aria-pressed': String(prefs.mode === mode),
    onclick: () => {
      prefs.mode = mode;
      for (const b of modeButtons) b.setAttribute('aria-pressed', String(b.dataset.mode === mode));
      onModeChange(mode);
    },
    dataset: { mode },
  }, mode === 'step' ? 'Step' : 'Hold to move'));
  const levels = state.config.jog.speed_levels.map((fraction, i) => el('button', {
    type: 'button', 'aria-pressed': String(prefs.level === i + 1), 'aria-label': `Speed ${i + 1} of 5`,
    title: `${Math.round(fraction * 100)} % of the jog speed`,
    onclick: (e) => {
      prefs.level = i + 1;
      for (const b of levelsBox.querySelectorAll('button')) b.setAttribute('aria-pressed', String(b === e.currentTarget));
    },
  }, String(i + 1)));
  const levelsBox = el('span', { class: 'row levels', role: 'group', 'aria-label': 'Speed' }, el('span', { class: 'label' }, 'Speed'), levels);
  return el('div', { class: 'modes' },
    el('span', { class: 'row', role: 'group', 'aria-label': 'Jog mode' }, modeButtons), levelsBox);
}

// rows: [{label, unit, digits, axis}] ; space: 'joint' | 'cartesian'; read(robot) -> values
export function jogGrid(space, rows, read) {
  const values = [];
  const grid = el('div', { class: 'jog-grid' });
  for (const row of rows) {
    const value = el('span', { class: 'value readout', 'aria-live': 'off' }, '–');
    values.push(value);
    const beat = (direction) => () => ({ robot: state.chosen, space, axis: row.axis, direction, level: prefs.level });
    const button = (direction) => {
      const b = el('button', {
        type: 'button', 'aria-label': `${row.label} ${direction < 0 ? 'minus' : 'plus'}`,
        onclick: () => {
          if (prefs.mode !== 'step' || !chosenRobot()) return;
          attemptOn(state.chosen, (robot) => api.post(paths.robot.step(robot),
            { space, axis: row.axis, direction, level: prefs.level }));
        },
      }, direction < 0 ? '−' : '+');
      holdable(b, beat(direction));
      return b;
    };
    grid.append(el('span', { class: 'label' }, `${row.label}${row.unit ? ` (${row.unit})` : ''}`),
      button(-1), value, button(1));
  }
  const update = (robot) => {
    const v = robot ? read(robot) : null;
    rows.forEach((row, i) => { values[i].textContent = v ? fmt(v[i], row.digits) : '–'; });
  };
  return { grid, update };
}

export function stopButton() {
  return el('button', {
    type: 'button', class: 'danger',
    onclick: () => state.chosen && attemptOn(state.chosen, (robot) => api.post(paths.robot.stop(robot))),
  }, 'Stop arm');
}

// Open and close the gripper of the robot the page commands (the Cartesian and Pointer tabs).
export function grip(close) {
  return attemptOn(state.chosen, (robot) => api.post(paths.robot.gripper(robot), { close }),
    close ? (r) => (r.holding ? 'Gripper closed: holding.' : 'Gripper closed: empty.') : 'Gripper open.');
}

export function gripperButtons() {
  return [el('button', { type: 'button', onclick: () => grip(false) }, 'Open gripper'),
    el('button', { type: 'button', onclick: () => grip(true) }, 'Close gripper')];
}
