// The person's access settings, kept per browser (localStorage) and carried between browsers as a
// JSON file. One checker (check) guards both: a bad file or a bad stored value never half-applies.
//
// Defaults are AsTeRICS-Grid's (its InputConfig): step scanning, row/column, 1000 ms, one switch
// (Space: tap = next, hold 400 ms = select), 3 rounds, then scanning waits for the next press.

const KEY = 'asibot.access';
const FORMAT = 'asibot-access-settings';
const VERSION = 1;

// name: [lowest, highest, step] of the numbers a person can set (the scanning time covers 10x the
// default each way, as WCAG 2.2.1 asks of a time limit).
export const LIMITS = {
  intervalMs: [100, 10000, 100],
  holdMs: [100, 3000, 100],
  rounds: [1, 10, 1],
  doubleTapMs: [100, 1000, 50],
  holdStopMs: [0, 10000, 500],
  dwellMs: [0, 5000, 250],
};

// The choices of each multiple-choice setting, in the order the Access page shows them.
export const CHOICES = {
  pattern: ['rowcol', 'linear', 'group'],
  mode: ['step', 'auto'],
  switches: [1, 2],
  afterSelect: ['resume', 'start', 'stay'],
  messages: ['fade', 'stay'],
  scope: ['page', 'home'],
};

export const DEFAULTS = Object.freeze({
  enabled: false,
  pattern: 'rowcol',
  mode: 'step',
  switches: 1,
  intervalMs: 1000,
  holdMs: 400,
  rounds: 3,
  afterSelect: 'resume',
  sound: false,
  next: Object.freeze({ kind: 'key', code: 'Space', label: 'Space' }),
  select: Object.freeze({ kind: 'key', code: 'Enter', label: 'Enter' }),
  messages: 'fade',
  // What the ring goes over: the whole page, or Home's tasks and places (one level deep).
  scope: 'page',
  // Two taps of the switch this close together (ms, release to press) stop every robot.
  doubleTapStop: true,
  doubleTapMs: 350,
  // A press held this long (ms) stops every robot; 0: off (a person with a tremor may hold on).
  holdStopMs: 0,
  // A pointer resting this long (ms) on a control chooses it (eye-gaze, a head pointer); 0: off.
  dwellMs: 0,
});

const NAMES = {
  pattern: 'the scanning order', mode: 'the scanning kind', switches: 'the number of switches',
  intervalMs: 'the scanning time (ms)', holdMs: 'the hold time (ms)', rounds: 'the number of rounds',
  afterSelect: 'what happens after a select', messages: 'how messages go away',
  next: 'the next switch', select: 'the select switch', enabled: 'scanning on or off', sound: 'the beep',
  scope: 'what the ring goes over', doubleTapStop: 'two quick taps stop', doubleTapMs: 'the time between two quick taps (ms)',
  holdStopMs: 'the long hold that stops (ms)', dwellMs: 'the dwell time (ms)',
};

class Invalid extends Error {}

function checkSwitch(name, value) {
  const bad = () => new Invalid(`${NAMES[name]} must be a key (its code) or a mouse button (0 to 4)`);
  if (!value || typeof value !== 'object' || Array.isArray(value)) throw bad();
  const label = value.label;
  if (typeof label !== 'string' || !label || label.length > 40) throw new Invalid(`${NAMES[name]} needs a name of 1 to 40 characters`);
  if (value.kind === 'key') {
    if (typeof value.code !== 'string' || !/^[A-Za-z0-9]{1,40}$/.test(value.code)) throw bad();
    // Esc is the emergency stop key everywhere on the page: it must stay that.
    if (value.code === 'Escape') throw new Invalid('Esc is the emergency stop key; it cannot be a switch');
    return Object.freeze({ kind: 'key', code: value.code, label });
  }
  if (value.kind === 'mouse') {
    if (!Number.isInteger(value.button) || value.button < 0 || value.button > 4) throw bad();
    return Object.freeze({ kind: 'mouse', button: value.button, label });
  }
  throw bad();
}

// A whole, valid settings object from `raw` (missing fields take the defaults), or Invalid with
// a sentence that says which field is wrong.
export function check(raw) {
  if (!raw || typeof raw !== 'object' || Array.isArray(raw)) throw new Invalid('it is not a settings object');
  const out = { ...DEFAULTS };
  for (const [name, value] of Object.entries(raw)) {
    if (name === 'format' || name === 'version') continue;
    if (!(name in DEFAULTS)) throw new Invalid(`it has a setting this page does not know: "${name}"`);
    if (name in LIMITS) {
      const [lo, hi, step] = LIMITS[name];
      if (!Number.isInteger(value) || value < lo || value > hi || value % step !== 0) {
        throw new Invalid(`${NAMES[name]} must be a whole number from ${lo} to ${hi}${step > 1 ? ` in steps of ${step}` : ''}`);
      }
      out[name] = value;
    } else if (name in CHOICES) {
      if (!CHOICES[name].includes(value)) throw new Invalid(`${NAMES[name]} must be one of ${CHOICES[name].map((c) => JSON.stringify(c)).join(', ')}`);
      out[name] = value;
    } else if (name === 'next' || name === 'select') {
      out[name] = checkSwitch(name, value);
    } else {
      if (typeof value !== 'boolean') throw new Invalid(`${NAMES[name]} must be true or false`);
      out[name] = value;
    }
  }
  if (out.switches === 2 && sameSwitch(out.next, out.select)) throw new Invalid('the next and select switches must differ');
  if (out.holdStopMs && out.holdStopMs < out.holdMs + 500) {
    throw new Invalid('the long hold that stops must be at least 500 ms longer than the hold that selects (or 0: off)');
  }
  return Object.freeze(out);
}

export function sameSwitch(a, b) {
  return a.kind === b.kind && (a.kind === 'key' ? a.code === b.code : a.button === b.button);
}

function load() {
  try {
    const text = localStorage.getItem(KEY);
    return text ? check(JSON.parse(text)) : DEFAULTS;
  } catch (e) {
    return DEFAULTS;   // a stored value from an older page: start from the defaults
  }
}

let current = load();
const listeners = new Set();

export function settings() { return current; }
export function onSettings(fn) { listeners.add(fn); return () => listeners.delete(fn); }

function commit(next) {
  current = next;
  localStorage.setItem(KEY, JSON.stringify(current));
  for (const fn of listeners) fn(current);
}

// Change some settings; an invalid change throws an Error with a sentence and changes nothing.
export function update(patch) {
  try {
    commit(check({ ...current, ...patch }));
  } catch (e) {
    if (e instanceof Invalid) throw new Error(`Not changed: ${e.message}.`);
    throw e;
  }
  return current;
}

export function reset() { commit(DEFAULTS); }

export function exportText() {
  return `${JSON.stringify({ format: FORMAT, version: VERSION, ...current }, null, 2)}\n`;
}

// The text of an exported file -> the settings in force, or an Error whose sentence says why the
// file was refused (and nothing changed).
export function importText(text) {
  let raw;
  try {
    raw = JSON.parse(text);
  } catch (e) {
    throw new Error('That file is not a settings file (it is not JSON). Nothing was changed.');
  }
  if (!raw || raw.format !== FORMAT) throw new Error('That file is not an ASIBOT access settings file. Nothing was changed.');
  if (raw.version !== VERSION) throw new Error(`That settings file is version ${raw.version}; this page reads version ${VERSION}. Nothing was changed.`);
  let next;
  try {
    next = check(raw);
  } catch (e) {
    if (e instanceof Invalid) throw new Error(`That settings file was refused: ${e.message}. Nothing was changed.`);
    throw e;
  }
  commit(next);
  return current;
}
