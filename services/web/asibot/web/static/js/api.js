// The page's link to the server: JSON over HTTP for actions, one WebSocket for live state.
// Every refusal comes back as an Error whose message is the server's sentence.

export class Refused extends Error {
  // `code`: the server's word for why (its "error": exists, not_found, ...), for a page that
  // answers one refusal with a question rather than a message.
  constructor(message, code = '') { super(message); this.code = code; }
}

// The server writes its session token into the page; another site's page cannot read it, so
// it cannot send it (services/web/guard.py). A page from before a server restart reloads.
const SESSION = document.querySelector('meta[name=asibot-session]')?.content || '';
const SESSION_REFUSED = 4403;

async function request(method, path, body, binary = false, tag = null) {
  const init = { method, headers: { 'X-Asibot-Session': SESSION } };
  if (tag) { init.headers['If-None-Match'] = tag; init.cache = 'no-store'; }
  if (body instanceof FormData) {
    init.body = body;
  } else if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  let reply;
  try {
    reply = await fetch(path, init);
  } catch (e) {
    throw new Refused('The server does not answer. Is `asibot up` still running?');
  }
  const type = reply.headers.get('Content-Type') || '';
  if (binary && reply.status === 304) return { data: null, tag };
  if (binary && reply.ok) return { data: await reply.arrayBuffer(), tag: reply.headers.get('ETag') };
  const data = type.includes('application/json') ? await reply.json() : await reply.text();
  if (!reply.ok) throw new Refused((data && data.message) || `The server answered ${reply.status}.`, (data && data.error) || '');
  return data;
}

// --- the server's paths, written here once (services/web/asibot/web/api_*.py) -----------------
// Every name in a path is encoded, so a point, program or task name with a space or a slash
// stays one part of it.
const at = (...parts) => `/api/${parts.map((p) => encodeURIComponent(p)).join('/')}`;

export const paths = {
  config: at('config'),
  estop: at('estop'),
  releaseAll: at('release'),
  favourites: at('favourites'),
  favouritesOrder: at('favourites', 'order'),
  phone: at('phone'),
  phoneQr: at('phone', 'qr.png'),
  voice: at('voice'),
  robot: {
    model: (id) => at('robots', id, 'model'),
    step: (id) => at('robots', id, 'step'),
    move: (id) => at('robots', id, 'move'),
    inverse: (id) => at('robots', id, 'inv'),
    home: (id) => at('robots', id, 'home'),
    stop: (id) => at('robots', id, 'stop'),
    gripper: (id) => at('robots', id, 'gripper'),
    release: (id) => at('robots', id, 'release'),
    resetFault: (id) => at('robots', id, 'reset_fault'),
    resetWorld: (id) => at('robots', id, 'reset_world'),
    cameras: (id) => at('robots', id, 'cameras'),
    camera: (id, name) => at('robots', id, 'cameras', `${name}.mjpg`),
    depthCameras: (id) => at('robots', id, 'depth-cameras'),
    cloud: (id, name) => at('robots', id, 'cameras', name, 'cloud'),
    touch: (id, name) => at('robots', id, 'cameras', name, 'touch'),
    calibration: (id, name) => at('robots', id, 'cameras', name, 'calibration'),
    calibrationSpot: (id, name) => at('robots', id, 'cameras', name, 'calibration', 'spot'),
    calibrationMarks: (id, name) => at('robots', id, 'cameras', name, 'calibration', 'marks'),
    calibrationSolve: (id, name) => at('robots', id, 'cameras', name, 'calibration', 'solve'),
    capture: (id) => at('robots', id, 'capture'),
    suggestedPointName: (id) => at('robots', id, 'suggested-point-name'),
    goToPoint: (id, point) => at('robots', id, 'points', point, 'go'),
  },
  points: at('points'),
  point: (name) => at('points', name),
  renamePoint: (name) => at('points', name, 'rename'),
  programs: at('programs'),
  program: (name) => at('programs', name),
  renameProgram: (name) => at('programs', name, 'rename'),
  runProgram: (name) => at('programs', name, 'run'),
  restoreVersion: (name, version) => at('programs', name, 'versions', version, 'restore'),
  storage: at('storage'),
  trash: at('trash'),
  programSteps: {
    steps: (name) => at('programs', name, 'steps'),
    preview: (name) => at('programs', name, 'steps', 'preview'),
    template: (name) => at('programs', name, 'steps', 'template'),
  },
  stepPrograms: at('step-programs'),
  check: at('check'),
  clientReference: at('client-reference'),
  run: at('run'),
  stopRun: at('run', 'stop'),
  words: at('words'),
  word: (text) => at('words', text),
  learnWord: at('voice', 'learn'),
  forgetWord: at('voice', 'forget'),
  learnedWords: at('voice', 'learned'),
  tasks: at('tasks'),
  task: (name) => at('tasks', name),
  launchTask: (name) => at('tasks', name, 'launch'),
  icons: at('icons'),
  icon: (name) => at('icons', name),
  importFiles: at('import'),
  exportFiles: at('export.zip'),
  base: {
    map: (id) => at('base', id, 'map'),
    goto: (id) => at('base', id, 'goto'),
    cancel: (id) => at('base', id, 'cancel'),
    localize: (id) => at('base', id, 'localize'),
    drive: (id) => at('base', id, 'drive'),
    settings: (id) => at('base', id, 'settings'),
    places: (id) => at('base', id, 'places'),
    place: (id, name) => at('base', id, 'places', name),
    renamePlace: (id, name) => at('base', id, 'places', name, 'rename'),
  },
};

export const api = {
  get: (path) => request('GET', path),
  // { data: an ArrayBuffer (the point cloud), tag: its ETag }; data is null when the server still
  // has the one tagged `tag` (304: nothing to draw again).
  bytes: (path, tag = null) => request('GET', path, undefined, true, tag),
  post: (path, body = {}) => request('POST', path, body),
  put: (path, body) => request('PUT', path, body),
  del: (path) => request('DELETE', path),
};

// --- shared state: robots, the robot the page commands, listeners ------------------------------
const listeners = new Set();
export const state = {
  config: null,
  robots: new Map(),          // id -> the server's view of the robot
  chosen: localStorage.getItem('asibot.robot') || null,
  feed: 'connecting',          // connecting | live | lost
  page: null,                  // this page's id on the server (names its microphone's stream)
};

export function onChange(fn) { listeners.add(fn); return () => listeners.delete(fn); }
function changed(what) { for (const fn of listeners) fn(what); }

export function chosenRobot() { return state.chosen ? state.robots.get(state.chosen) || null : null; }

export function choose(robotId) {
  state.chosen = robotId;
  localStorage.setItem('asibot.robot', robotId);
  changed('chosen');
}

// --- the live feed ------------------------------------------------------------------------------
const messageListeners = new Set();
export function onMessage(fn) { messageListeners.add(fn); return () => messageListeners.delete(fn); }

let socket = null;
export function connectFeed() {
  const url = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws?session=${SESSION}`;
  socket = new WebSocket(url);
  socket.onopen = () => { state.feed = 'live'; changed('feed'); };
  socket.onclose = (event) => {
    state.feed = 'lost'; changed('feed');
    if (event.code === SESSION_REFUSED) { location.reload(); return; }   // the server restarted
    setTimeout(connectFeed, 1000);   // the server restarted or the network blinked: come back
  };
  socket.onmessage = (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === 'hello') {
      state.page = msg.page;
    } else if (msg.type === 'robots') {
      state.robots = new Map(msg.robots.map((r) => [r.id, r]));
      pickDefault();
      changed('robots');
    } else if (msg.type === 'robot') {
      state.robots.set(msg.robot.id, msg.robot);
      pickDefault();
      changed(msg.robot.id === state.chosen ? 'chosen-state' : 'robots');
    }
    for (const fn of messageListeners) fn(msg);
  };
}

export function sendLive(message) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
}

// Raw bytes (the microphone's frames); dropped while the connection is down, as live sound is.
export function sendSound(buffer) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(buffer);
}

// A robot the page can command: its driver or its controller is alive (the server's Fleet.ids).
export function isConnected(robot) { return Boolean(robot && (robot.driver || robot.controller)); }

export function connectedRobots() { return [...state.robots.values()].filter(isConnected); }

// Without a choice, command the first connected arm, preferring a simulated one.
function pickDefault() {
  const current = state.chosen && state.robots.get(state.chosen);
  if (current) return;   // the user's choice, kept while it reconnects
  const live = connectedRobots().filter((r) => r.arm);
  const pick = live.find((r) => r.simulated && r.arm === 'asibot') || live.find((r) => r.simulated) || live[0];
  if (pick) { state.chosen = pick.id; changed('chosen'); }
}
