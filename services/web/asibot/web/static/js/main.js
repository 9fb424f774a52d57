// The page: tabs as client-side views (a tab change loads no page), the Connection Manager, the
// emergency stop (button and Esc key: estop.js), and the live feed that keeps every view current.
import { api, chosenRobot, connectFeed, onChange, onMessage, paths, state } from './api.js';
import { mountConnection } from './connection.js';
import { startDwell } from './dwell.js';
import { startEmergencyStop } from './estop.js';
import { startScanning } from './scanning.js';
import { about, el, notify } from './ui.js';
import { viewer } from './viewer3d.js';
import { render as renderWizard } from './wizard.js';
import home from './views/home.js';
import joint from './views/joint.js';
import cartesian from './views/cartesian.js';
import pointer from './views/pointer.js';
import program from './views/program.js';
import speech from './views/speech.js';
import assigner from './views/assigner.js';
import launcher from './views/launcher.js';
import video from './views/video.js';
import pioneer from './views/pioneer.js';
import base from './views/base.js';
import access from './views/access.js';

const VIEWS = [home, joint, cartesian, pointer, program, speech, assigner, launcher, video, pioneer, base, access];
let active = null;   // { view, handle }

function show(id) {
  const view = VIEWS.find((v) => v.id === id) || home;
  if (active && active.view === view) return;
  if (active && active.handle.unmount) active.handle.unmount();
  for (const tab of document.querySelectorAll('#tabs button')) {
    const on = tab.dataset.view === view.id;
    tab.setAttribute('aria-selected', String(on));
    tab.tabIndex = on ? 0 : -1;
    if (on) tab.scrollIntoView({ block: 'nearest', inline: 'nearest' });   // a phone's scrolled tab row
  }
  const root = document.getElementById('view');
  root.setAttribute('aria-labelledby', `tab-${view.id}`);
  active = { view, handle: view.mount(root) || {} };
  if (active.handle.update) active.handle.update(chosenRobot());
  renderWizard();
}

function tabs() {
  const bar = document.getElementById('tabs');
  bar.replaceChildren(...VIEWS.map((v) => el('button', {
    type: 'button', role: 'tab', id: `tab-${v.id}`, 'aria-controls': 'view', dataset: { view: v.id },
    onclick: () => { location.hash = v.id; },
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
  state.config = await api.get(paths.config);
  tabs();
  mountConnection(document.getElementById('connection'));
  startScanning();
  startDwell();
  startEmergencyStop();
  window.addEventListener('hashchange', () => show(location.hash.slice(1)));
  let shownRobot;
  onChange((what) => {
    if (what === 'feed') feedState();
    const robot = chosenRobot();
    if (robot && robot.id !== shownRobot) { shownRobot = robot.id; viewer().show(robot.id).catch((e) => notify(e.message)); }
    if (robot && robot.joints) viewer().setJoints(robot.joints.names, robot.joints.deg);
    if (active && active.handle.update) active.handle.update(robot);
  });
  // A streamed motion (a held jog button, the pointer) that the server refused: say why.
  onMessage((msg) => { if (msg.type === 'refused') notify(about(msg.robot, msg.text)); });
  connectFeed();
  show(location.hash.slice(1) || 'home');
  document.body.dataset.ready = 'true';
}

start().catch((e) => notify(`The page could not start: ${e.message}`));
