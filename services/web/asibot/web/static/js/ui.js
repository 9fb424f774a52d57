// Small helpers to build the DOM and tell the user what happened.
import { settings } from './settings.js';

// el('button', {class: 'primary', onclick: f}, 'Run') -> <button class="primary">Run</button>
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value === undefined || value === null || value === false) continue;
    if (key.startsWith('on')) node.addEventListener(key.slice(2), value);
    else if (key === 'class') node.className = value;
    else if (key === 'dataset') Object.assign(node.dataset, value);
    else if (value === true) node.setAttribute(key, '');
    else node.setAttribute(key, value);
  }
  for (const child of children.flat()) {
    if (child === null || child === undefined || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

// Good news fades after FADE_MS unless the person keeps messages (Access page), and never while
// the pointer is on it, focus is in it or the scanning ring is on it (WCAG 2.2.1: no time limit
// the person cannot stop). Errors stay until dismissed.
export const FADE_MS = 4000;
let noticeTimer = null;

function fadeLater(box) {
  clearTimeout(noticeTimer);
  noticeTimer = setTimeout(() => {
    if (box.matches(':hover, :focus-within') || box.querySelector('[data-scanned]')) return;   // leaving restarts it
    box.hidden = true;
  }, FADE_MS);
}

function fades(box) { return box.classList.contains('info') && settings().messages === 'fade'; }

let watched = false;
function watch(box) {
  if (watched) return;
  watched = true;
  const hold = () => clearTimeout(noticeTimer);
  const resume = () => { if (!box.hidden && fades(box)) fadeLater(box); };
  box.addEventListener('pointerenter', hold);
  box.addEventListener('focusin', hold);
  box.addEventListener('pointerleave', resume);
  box.addEventListener('focusout', resume);
}

// Show a sentence under the tabs: kind 'error' (stays), 'stop' (red, stays) or 'info' (good news).
// `undo`: { label, run } adds a button that takes back what was just done (a deletion).
export function notify(text, kind = 'error', undo = null) {
  const box = document.getElementById('notice');
  watch(box);
  const back = undo && el('button', { type: 'button', onclick: () => { box.hidden = true; undo.run(); } }, undo.label);
  box.replaceChildren(el('span', {}, text), ...(back ? [back] : []),
    el('button', { type: 'button', onclick: () => { box.hidden = true; } }, 'Dismiss'));
  box.className = { error: 'notice', stop: 'notice stop', info: 'notice info' }[kind];
  box.setAttribute('role', kind === 'info' ? 'status' : 'alert');
  box.hidden = false;
  clearTimeout(noticeTimer);
  if (fades(box)) fadeLater(box);
}

// A button that asks first: the first press arms it ("Sure? Touch again"), the second does it.
// It stays armed until the person presses something else: no time limit, so a switch user who
// scans back to it is not hurried. `ask`: the armed button's words; `needed()`: whether to ask
// at all this time (false: the first press does it).
export function confirmable(label, attrs, action, { ask = 'Sure? Touch again', needed = () => true } = {}) {
  const name = attrs['aria-label'];
  let armed = false;
  const disarm = (e) => {
    if (e && b.contains(e.target)) return;
    armed = false;
    b.textContent = label;
    if (name) b.setAttribute('aria-label', name);
    document.removeEventListener('click', disarm, true);
  };
  const b = el('button', {
    type: 'button', class: 'danger', ...attrs,
    onclick: () => {
      if (armed || !needed()) { disarm(); action(); return; }
      armed = true;
      b.textContent = ask;
      if (name) b.setAttribute('aria-label', `${ask}: ${name}`);
      document.addEventListener('click', disarm, true);
    },
  }, label);
  return b;
}

// Run an action; a refusal becomes a notice with the server's sentence, never a console error.
export async function attempt(action, success) {
  try {
    const result = await action();
    const said = typeof success === 'function' ? success(result) : success;
    if (said) notify(said, 'info');      // nothing to say: the action asked a question instead
    return result;
  } catch (e) {
    notify(e.message);
    return undefined;
  }
}

// A sentence about a robot names it: "asibot-sim: Out of the arm's reach." (unless it does).
export function about(robot, text) {
  if (!robot || !text || text.includes(robot)) return text;
  return `${robot}: ${text}`;
}

// attempt() of an action on one robot (the one the page commands, or the one a tab is about):
// its success and its refusal both name the robot. No robot: the person is told to choose one.
export function attemptOn(robot, action, success) {
  return attempt(async () => {
    if (!robot) throw new Error('No robot commanded: press Command beside one in the Connection Manager first.');
    try {
      return await action(robot);
    } catch (e) {
      e.message = about(robot, e.message);
      throw e;
    }
  }, success && ((r) => about(robot, typeof success === 'function' ? success(r) : success)));
}

export function fmt(value, digits = 3) {
  return value === null || value === undefined ? '–' : Number(value).toFixed(digits);
}
