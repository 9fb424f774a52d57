// The page: tabs as client-side views (a tab change loads no page), the Connection Manager, the
// emergency stop (button and Esc key: estop.js), and the live feed that keeps every view current.
import { api, chosenRobot, connectFeed, onChange, onMessage, paths, state } from './api.js';
import { mountConnection } from './connection.js';
import { startDwell } from './dwell.js';
import { startEmergencyStop } from './estop.js';
import { startScanning } from './scanning.js';
import { about, el, notify } from './ui.js';
import { render as renderWizard } from './wizard.js';

// The pages, in the tabs' order. A page's module is loaded when it is first shown, so a page that
// never shows the 3D view or the program editor never parses three.js or CodeMirror (1.3 MB).
// A module that failed is asked for again under another URL: a browser keeps a failed import.
const VIEWS = [
  { id: 'home', title: 'Home', module: './views/home.js' },
  { id: 'joint', title: 'Joint', module: './views/joint.js' },
  { id: 'cartesian', title: 'Cartesian', module: './views/cartesian.js' },
  { id: 'pointer', title: 'Pointer', module: './views/pointer.js' },
  { id: 'program', title: 'Program', module: './views/program.js' },
  { id: 'speech', title: 'Speech', module: './views/speech.js' },
  { id: 'assigner', title: 'Assigner', module: './views/assigner.js' },
  { id: 'launcher', title: 'Launcher', module: './views/launcher.js' },
  { id: 'video', title: 'Video', module: './views/video.js' },
  { id: 'pioneer', title: 'Pioneer arm', module: './views/pioneer.js' },
  { id: 'base', title: 'Base', module: './views/base.js' },
  { id: 'access', title: 'Access', module: './views/access.js' },
];
let active = null;   // { view, handle }
const failures = new Map();   // view id -> how many times its module could not load

function load(view) {
  const tries = failures.get(view.id) || 0;
  return import(tries ? `${view.module}?try=${tries}` : view.module);
}

let wanted = null;    // the view last asked for: a slow load that another choice overtook is not shown

// The chosen tab's view replaces the shown one at once (a "Loading" line while its module comes
// the first time), so nothing of the old view stays on screen under the new tab.
async function show(id) {
  const view = VIEWS.find((v) => v.id === id) || VIEWS[0];
  if (wanted === view) return;
  wanted = view;
  for (const tab of document.querySelectorAll('#tabs button')) {
    const on = tab.dataset.view === view.id;
    tab.setAttribute('aria-selected', String(on));
    tab.tabIndex = on ? 0 : -1;
    if (on) tab.scrollIntoView({ block: 'nearest', inline: 'nearest' });   // a phone's scrolled tab row
  }
  if (active && active.handle.unmount) active.handle.unmount();
  active = null;
  const root = document.getElementById('view');
  root.setAttribute('aria-labelledby', `tab-${view.id}`);
  root.setAttribute('aria-busy', 'true');
  root.replaceChildren(el('p', { class: 'muted' }, `Loading the ${view.title} page…`));
  let module;
  try {
    ({ default: module } = await load(view));
  } catch (e) {
    failures.set(view.id, (failures.get(view.id) || 0) + 1);
    if (wanted !== view) return;
    wanted = null;   // choosing the tab again tries again
    root.replaceChildren(el('p', { role: 'alert' }, `The ${view.title} page could not load (${e.message}). Check the connection, then choose its tab again (or reload the page).`));
    root.removeAttribute('aria-busy');
    return;
  }
  if (wanted !== view) return;
  root.replaceChildren();
  root.removeAttribute('aria-busy');
  active = { view, handle: module.mount(root) || {} };
  if (active.handle.update) active.handle.update(chosenRobot());
  renderWizard();
}

function tabs() {
  const bar = document.getElementById('tabs');
  bar.replaceChildren(...VIEWS.map((v) => el('button', {
    type: 'button', role: 'tab', id: `tab-${v.id}`, 'aria-controls': 'view', dataset: { view: v.id },
    // The shown tab chosen again: no hashchange comes, so show it here (a failed page tries again).
    onclick: () => { if (location.hash.slice(1) === v.id) show(v.id); else location.hash = v.id; },
  }, v.title)));
  // Arrow keys move between tabs, as the ARIA tabs pattern says.
  bar.addEventListener('keydown', (e) => {
    if (e.key !== 'ArrowRight' && e.key !== 'ArrowLeft') return;
    // From the focused tab, not the shown view: the view follows the hash a moment later.
    const from = VIEWS.findIndex((v) => v.id === e.target.dataset.view);
    const i = from + (e.key === 'ArrowRight' ? 1 : -1);
    const next = VIEWS[(i + VIEWS.length) % VIEWS.length];
    location.hash = next.id;
    document.getElementById(`tab-${next.id}`).focus();
  });
}

function feedState() {
  const text = { connecting: 'Connecting to the server…', live: 'Live', lost: 'Connection to the server lost; reconnecting…' }[state.feed];
  document.getElementById('feed-state').textContent = text;
}

async function start() {
  // The first view's module comes while the config does (show() below takes it from the
  // browser's module map); a failure is left to show(), which says so.
  const first = location.hash.slice(1) || 'home';
  load(VIEWS.find((v) => v.id === first) || VIEWS[0]).catch(() => {});
  state.config = await api.get(paths.config);
  tabs();
  mountConnection(document.getElementById('connection'));
  startScanning();
  startDwell();
  startEmergencyStop();
  window.addEventListener('hashchange', () => show(location.hash.slice(1)));
  onChange((what) => {
    if (what === 'feed') feedState();
    const robot = chosenRobot();
    if (active && active.handle.update) active.handle.update(robot);
  });
  // A streamed motion (a held jog button, the pointer) that the server refused: say why.
  onMessage((msg) => { if (msg.type === 'refused') notify(about(msg.robot, msg.text)); });
  connectFeed();
  await show(location.hash.slice(1) || 'home');
  document.body.dataset.ready = 'true';
}

start().catch((e) => notify(`The page could not start: ${e.message}`));
