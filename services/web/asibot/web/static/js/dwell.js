// Dwell to choose: for eye-gaze or a head pointer (any device that moves the mouse pointer), a
// control is chosen when the pointer rests on it for the person's dwell time; a ring fills round
// it meanwhile, and moving off cancels. The same controls and the same meaning as a switch's
// select (choose.js): a hold-to-move button starts, and the next dwell, on anything, stops it.
// A control just chosen is chosen again only after the pointer has left it. Touch never dwells.
// Off (dwell time 0) this module does nothing.
import { ACTIONABLE, chooseControl, usable } from './choose.js';
import { settings } from './settings.js';

const dwell = {
  target: null,    // the control the pointer rests on, its time running
  timer: null,
  spent: null,     // the control last chosen, until the pointer leaves it
  latched: null,   // stop() of a hold-to-move that a dwell started
};

function cancel() {
  clearTimeout(dwell.timer);
  if (dwell.target) dwell.target.classList.remove('dwelling');
  dwell.target = dwell.timer = null;
}

function chosen(node) {
  cancel();
  dwell.spent = node;
  if (dwell.latched) {                         // a movement runs: this dwell stops it
    const stopIt = dwell.latched;
    dwell.latched = null;
    stopIt();
    return;
  }
  chooseControl(node, (stopIt) => {
    dwell.latched = stopIt;
    return () => { if (dwell.latched === stopIt) dwell.latched = null; };
  });
}

function rest(e) {
  const ms = settings().dwellMs;
  if (!ms || e.pointerType === 'touch') return;
  const node = e.target instanceof Element ? e.target.closest(ACTIONABLE) : null;
  if (node !== dwell.spent) dwell.spent = null;
  if (!node || node === dwell.spent || !usable(node)) { cancel(); return; }
  if (node === dwell.target) return;           // still resting on it: its time runs on
  cancel();
  dwell.target = node;
  node.style.setProperty('--dwell-ms', `${ms}ms`);
  node.classList.add('dwelling');
  dwell.timer = setTimeout(() => chosen(node), ms);
}

export function startDwell() {
  document.addEventListener('pointermove', rest, true);
  document.addEventListener('pointerover', rest, true);
  // The pointer left the page: nothing is chosen by where it last was.
  document.documentElement.addEventListener('pointerleave', () => { cancel(); dwell.spent = null; });
}
