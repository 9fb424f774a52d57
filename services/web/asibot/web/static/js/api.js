// The page's link to the server: JSON over HTTP for actions, one WebSocket for live state.
// Every refusal comes back as an Error whose message is the server's sentence.

export class Refused extends Error {}

// The server writes its session token into the page; another site's page cannot read it, so
// it cannot send it (services/web/guard.py). A page from before a server restart reloads.
const SESSION = document.querySelector('meta[name=asibot-session]')?.content || '';
const SESSION_REFUSED = 4403;

async function request(method, path, body) {
  const init = { method, headers: { 'X-Asibot-Session': SESSION } };
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
  const data = type.includes('application/json') ? await reply.json() : await reply.text();
  if (!reply.ok) throw new Refused((data && data.message) || `The server answered ${reply.status}.`);
  return data;
}

export const api = {
  get: (path) => request('GET', path),
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

function connected(r) { return r.driver || r.controller; }

// Without a choice, command the first connected arm, preferring a simulated one.
function pickDefault() {
  const current = state.chosen && state.robots.get(state.chosen);
  if (current && connected(current)) return;
  if (current && !connected(current)) return;   // keep the user's choice while it reconnects
  const live = [...state.robots.values()].filter(connected).filter((r) => r.arm);
  const pick = live.find((r) => r.simulated && r.arm === 'asibot') || live.find((r) => r.simulated) || live[0];
  if (pick) { state.chosen = pick.id; changed('chosen'); }
}
