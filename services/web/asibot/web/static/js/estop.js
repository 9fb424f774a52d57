// The emergency stop: the red button at the top and the Esc key.
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
import { api, paths } from './api.js';
import { attempt } from './ui.js';

const TEXT_INPUTS = new Set(['text', 'number', 'search', 'email', 'url', 'tel', 'password']);
const MODIFIERS = new Set(['Shift', 'Control', 'Alt', 'Meta', 'AltGraph', 'CapsLock']);

export function emergencyStop() {
  return attempt(() => api.post(paths.estop), (r) => `Emergency stop: ${r.robots.length ? r.robots.join(', ') : 'no robot'} stopped. Release it in the Connection Manager.`);
}

// Whether `node` takes typed text: a text field, a text area or an editor (contenteditable).
function typing(node) {
  if (!node || node === document.body) return false;
  if (node.tagName === 'TEXTAREA' || node.isContentEditable) return true;
  return node.tagName === 'INPUT' && TEXT_INPUTS.has(node.type);
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
  // Bubbling, on the document: the editor, a list or a name being changed saw the key first.
  document.addEventListener('keydown', (e) => {
    if (e.key !== 'Escape') return;
    if (armed || !(e.defaultPrevented || typing(e.target))) {
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
