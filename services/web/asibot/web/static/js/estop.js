// The emergency stop: the red button at the top and the Esc key; next to it, while a robot is
// stopped, "Release all".
//
// The rule for Esc (the Home page's Safety text says it to the person, in these words):
// one Esc stops every robot, except when the focus is in a text field or the program editor, or
// when that Esc closes or cancels something (the editor's completion list or search box, a name
// being changed): then that Esc only does that, and the next Esc stops, wherever the focus is.
// Two Esc presses in a row always stop. Any other key, or a click, in between starts over.
//
// The page's own Esc handlers say they used the key with preventDefault() (CodeMirror does the
// same when its keymap closes something), never with stopPropagation(): this listener must hear
// every Esc to keep the second one a stop.
import { api, connectedRobots, onChange, paths } from './api.js';
import { takesText } from './choose.js';
import { attempt, notify } from './ui.js';

const MODIFIERS = new Set(['Shift', 'Control', 'Alt', 'Meta', 'AltGraph', 'CapsLock']);

export async function emergencyStop() {
  try {
    const r = await api.post(paths.estop);
    // Red, and it stays: a stop is never good news that fades.
    notify(`Emergency stop: ${r.robots.length ? r.robots.join(', ') : 'no robot'} stopped. Release all (at the top) lets them move again.`, 'stop');
    return r;
  } catch (e) {
    notify(e.message);
    return undefined;
  }
}

export function releaseAll() {
  return attempt(() => api.post(paths.releaseAll),
    (r) => `Released: ${r.robots.length ? r.robots.join(', ') : 'no robot was stopped'}. Nothing moves until you ask it to.`);
}

// The bar at the top says, for as long as it lasts, which robots are stopped; "Release all" is
// next to the stop (its room kept while nothing is stopped, so nothing jumps when it comes).
function showStopped(button) {
  const header = document.querySelector('header.top');
  let last = null;
  onChange(() => {
    const stopped = connectedRobots().filter((r) => r.estop.engaged).map((r) => r.id);
    const key = stopped.join(',');
    if (key === last) return;
    last = key;
    button.dataset.idle = String(!stopped.length);
    button.disabled = !stopped.length;
    header.classList.toggle('stopped', stopped.length > 0);
    const notice = document.getElementById('notice');
    if (!stopped.length && notice.classList.contains('stop')) notice.hidden = true;   // its news is over
  });
}

export function startEmergencyStop() {
  const button = document.getElementById('estop');
  const hint = document.getElementById('estop-hint');
  let armed = false;
  const arm = (on) => {
    if (armed === on) return;
    armed = on;
    hint.textContent = on ? 'Esc again: emergency stop' : '';
    button.classList.toggle('armed', on);
  };
  button.addEventListener('click', () => { arm(false); emergencyStop(); });
  const release = document.getElementById('release-all');
  release.addEventListener('click', releaseAll);
  showStopped(release);
  // Bubbling, on the document: the editor, a list or a name being changed saw the key first.
  document.addEventListener('keydown', (e) => {
    if (e.key !== 'Escape') return;
    if (armed || !(e.defaultPrevented || takesText(e.target))) {
      arm(false);
      emergencyStop();
      return;
    }
    arm(true);
  });
  // Anything else the person does in between: the next Esc is a first one again.
  window.addEventListener('keydown', (e) => { if (e.key !== 'Escape' && !MODIFIERS.has(e.key)) arm(false); }, true);
  window.addEventListener('pointerdown', (e) => { if (e.target !== button) arm(false); }, true);
}
