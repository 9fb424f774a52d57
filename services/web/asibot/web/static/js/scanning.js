// Switch scanning: one controller for every page, for people who use one or two switches (a big
// button, a sip-and-puff, a head switch) that send a key or a mouse button.
//
// A ring moves over the page's controls; the person selects the one ringed. Patterns: row/column
// (a row first, then a control in it), linear (control by control) and group (the page's regions:
// Connection Manager, tabs, each panel, then its rows). The Emergency stop is always the first
// thing ringed, on its own, so it is one select away whenever scanning starts or starts over.
// Moves: step (the switch moves the ring) or automatic (a timer does). One switch: tap = next,
// hold = select (AsTeRICS-Grid's scheme); in automatic scanning any press selects. Two switches:
// next and select. After `rounds` rounds without a select, scanning stops and waits for a press.
// After a select the ring starts over at the stop and, by default, goes on from where the person
// works: the control the page moved the keyboard focus to (a new step, the first choice of a
// list just opened), else the control selected; the rest of the page follows, round to the top.
// Every opened row or group ends with Back; right after a select changed the page, "Undo: back
// to <page>" follows the stop and puts the page and the ring back as they were. A long list (a
// labelled group of more than BLOCK_ROWS rows: a dozen programs) is one entry, "Programs (12)",
// that a select opens (block scanning, as AAC grids do): passing it costs one press, not twelve.
// A list that is what its page is for (the Launcher's tasks) says data-scan="rows": never a block.
//
// Controls that act while held (jog "Hold to move") take the 'scan:select' event: they start, and
// the next press of any switch stops them (select-to-start, select-to-stop). When scanning is off
// this module does nothing at all: no listener acts, no key is taken.
import { ACTIONABLE, chooseControl, usable } from './choose.js';
import { emergencyStop } from './estop.js';
import { onSettings, settings } from './settings.js';
import { el } from './ui.js';

// Ringed first at every level that starts over: the stop, and Release all while a robot is stopped.
const FIRST = ['estop', 'release-all'];
const MAX_GROUP = 8;          // a group with more controls than this is scanned row by row inside
const BLOCK_ROWS = 4;         // a labelled group of more rows than this is one entry (a block)
export const MOUSE_BUTTONS = ['Left mouse button', 'Middle mouse button', 'Right mouse button', 'Back mouse button', 'Forward mouse button'];

// --- what can be scanned -----------------------------------------------------------------------
function controls(root) {
  return [...root.querySelectorAll(ACTIONABLE)].filter((n) => !FIRST.includes(n.id) && !n.closest('#scan-ring') && usable(n));
}

function nameOf(node) {
  const label = node.getAttribute('aria-label') || (node.labels && node.labels[0] && node.labels[0].textContent)
    || node.innerText || node.getAttribute('placeholder') || node.getAttribute('title') || node.tagName.toLowerCase();
  let text = label.replace(/\s+/g, ' ').trim();
  if (node.tagName === 'SELECT' && node.selectedOptions[0]) text = `${text}: ${node.selectedOptions[0].textContent.trim()}`;
  return text.length > 48 ? `${text.slice(0, 47)}…` : text;
}

function regionName(node) {
  const heading = node.querySelector('h2, h3');
  return node.getAttribute('aria-label') || (heading && heading.textContent.trim()) || 'Controls';
}

// Consecutive controls (in reading order) whose boxes share a line make a row: the rows of a
// two-column page stay in their column.
function rowsOf(nodes) {
  const rows = [];
  let row = null;
  for (const node of nodes) {
    const r = node.getBoundingClientRect();
    if (row && r.top < row.bottom - 2 && r.bottom > row.top + 2) {
      row.nodes.push(node);
      row.top = Math.min(row.top, r.top);
      row.bottom = Math.max(row.bottom, r.bottom);
    } else {
      row = { nodes: [node], top: r.top, bottom: r.bottom };
      rows.push(row);
    }
  }
  return rows.map((x) => x.nodes);
}

// An entry is what the ring stands on: one control, or a row or group that a select opens.
function item(node) { return { nodes: [node], label: nameOf(node) }; }

function rowEntry(nodes) {
  if (nodes.length === 1) return item(nodes[0]);
  return { nodes, label: `Row: ${nodes.map(nameOf).join(', ')}`, open: () => nodes.filter((n) => n.isConnected && usable(n)).map(item) };
}

function groupEntry(nodes, box, label, collect) {
  if (!nodes.length) return null;
  if (nodes.length === 1) return item(nodes[0]);
  return {
    nodes, box, label: `${label} (${nodes.length})`,
    open: () => { const now = collect(); return now.length > MAX_GROUP ? blocked(now, rowLines) : now.map(item); },
  };
}

// How a run of controls is scanned: row by row (row/column), or one by one (linear).
function rowLines(nodes) { return rowsOf(nodes).map(rowEntry); }
function itemLines(nodes) { return nodes.map(item); }

// The long lists among `nodes`: labelled groups of more than BLOCK_ROWS rows, outermost first.
function longLists(nodes) {
  const lists = [];
  for (const group of document.querySelectorAll('[role=group][aria-label]:not([data-scan=rows])')) {
    if (lists.some((l) => l.contains(group))) continue;
    const inside = nodes.filter((n) => group.contains(n));
    if (inside.length > BLOCK_ROWS && rowsOf(inside).length > BLOCK_ROWS) lists.push(group);
  }
  return lists;
}

// `nodes` as entries by `lines`, with each long list one entry in its place that opens into
// its own lines; its label counts what it holds.
function blocked(nodes, lines) {
  const lists = longLists(nodes);
  if (!lists.length) return lines(nodes);
  const entries = [];
  let run = [];
  const flush = () => { entries.push(...lines(run)); run = []; };
  const placed = new Set();
  for (const node of nodes) {
    const list = lists.find((l) => l.contains(node));
    if (!list) { run.push(node); continue; }
    if (placed.has(list)) continue;
    placed.add(list);
    flush();
    const inside = nodes.filter((n) => list.contains(n));
    entries.push({ nodes: inside, box: list, list: true, label: `${list.getAttribute('aria-label')} (${inside.length})`,
                   open: () => lines(controls(list)) });
  }
  flush();
  return entries;
}

// The page's regions for group scanning: the header's, then each top section of the view, then
// whatever is left.
function groups() {
  const regions = ['#connection', '#tabs', '#wizard', '#notice'].map((s) => document.querySelector(s));
  const view = document.getElementById('view');
  regions.push(...[...view.querySelectorAll('section')].filter((s) => !s.parentElement.closest('#view section')));
  const entries = [];
  const placed = new Set();
  for (const region of regions) {
    if (!region) continue;
    const collect = () => controls(region);
    const nodes = collect();
    nodes.forEach((n) => placed.add(n));
    const name = region.id === 'tabs' ? 'Pages' : region.id === 'notice' ? 'Message' : regionName(region);
    entries.push(groupEntry(nodes, region, name, collect));
  }
  const rest = () => controls(document.body).filter((n) => !placed.has(n));
  entries.push(groupEntry(rest(), null, 'Other controls', rest));
  return entries.filter(Boolean);
}

function firstEntries() {
  const first = FIRST.map((id) => document.getElementById(id)).filter((n) => n && usable(n)).map(item);
  // Right after a page was chosen, the way back to the one before comes next (one tap, no side
  // effect): a select held a moment too long on the wrong tab costs two presses, not a round.
  if (scan.undo && scan.undo.tab.isConnected) first.push({ nodes: [scan.undo.tab], label: scan.undo.label, undo: true });
  return first;
}

function pageEntries() {
  const pattern = settings().pattern;
  let entries;
  if (pattern === 'group') entries = groups();
  else entries = blocked(controls(document.body), pattern === 'rowcol' ? rowLines : itemLines);
  return fromResume(entries);
}

// Where the person works after a select (see the top): the focus the page moved, else the
// control selected, while it is still on the page; null when the ring starts at the top.
function resumeAt() {
  if (!scan.resumeFrom) return null;
  const focused = document.activeElement;
  if (focused && focused !== document.body && !focused.closest('#scan-ring')) return focused;
  return scan.resumeFrom.isConnected ? scan.resumeFrom : null;
}

// The entries from the first that holds `resumeAt()` or comes after it in the page, then the
// ones before it: the page read on from where the person is, round to its top.
function fromResume(entries) {
  const at = resumeAt();
  if (!at) return entries;
  const after = (n) => n === at || n.contains(at) || at.contains(n)
    || Boolean(at.compareDocumentPosition(n) & Node.DOCUMENT_POSITION_FOLLOWING);
  const k = entries.findIndex((e) => [e.box, ...e.nodes].some((n) => n && after(n)));
  return k <= 0 ? entries : [...entries.slice(k), ...entries.slice(0, k)];
}

// Home mode: the person's tasks and places (Home's panel, favourites.js) one level deep, and
// the whole page one select away. Away from Home, the Home tab is offered instead.
function homeEntries() {
  const mine = document.getElementById('for-me');
  const entries = mine && usable(mine) ? controls(mine).map(item)
    : [{ ...item(document.getElementById('tab-home')), label: 'Home: your tasks and places' }];
  const tabs = document.getElementById('tabs');
  entries.push({ nodes: [tabs], label: 'The whole page', page: true, open: () => [...firstEntries(), ...pageEntries()] });
  return entries;
}

function topEntries() {
  return [...firstEntries(), ...(settings().scope === 'home' ? homeEntries() : pageEntries())];
}

// An opened row or group ends with Back (the ring around the row again): one round leaves it.
function withBack(entry) {
  const back = {
    nodes: entry.nodes, box: entry.box, back: true,
    label: entry.page ? 'Back to your tasks and places' : `Back: leave this ${entry.list ? 'list' : entry.box ? 'group' : 'row'}`,
  };
  return () => [...entry.open(), back];
}

// Where an opened row starts: after the control that is current there (the shown tab), so the
// tab row scans from the page the person is on; else on the control where the person works,
// and in a long list on its row.
function startOf(inside, list = false) {
  const current = inside.findIndex((e) => e.nodes.length === 1
    && (e.nodes[0].getAttribute('aria-selected') === 'true' || e.nodes[0].getAttribute('aria-current') === 'page'));
  if (current >= 0) return (current + 1) % inside.length;
  const at = resumeAt();
  const here = (e) => (list ? e.nodes.some((n) => n === at || n.contains(at)) : e.nodes.length === 1 && e.nodes[0] === at);
  return Math.max(0, inside.findIndex(here));
}

// --- the ring ----------------------------------------------------------------------------------
const chip = el('span', { class: 'scan-chip' });
const ring = el('div', { id: 'scan-ring', class: 'scan-ring', 'aria-hidden': 'true', hidden: true, dataset: { chip: 'above-left' } }, chip);

function boxOf(entry) {
  const rects = entry.box ? [entry.box.getBoundingClientRect()] : entry.nodes.map((n) => n.getBoundingClientRect());
  const left = Math.min(...rects.map((r) => r.left)), top = Math.min(...rects.map((r) => r.top));
  const right = Math.max(...rects.map((r) => r.right)), bottom = Math.max(...rects.map((r) => r.bottom));
  return { left: left + window.scrollX, top: top + window.scrollY, width: right - left, height: bottom - top };
}

// What the ring's label must not cover: news and states (a robot's name, its STOPPED lamp, a
// status line) count ten times as much as another control.
const MATTERS = '[role=status]:not([hidden]), [aria-live]:not([hidden]), .robot-card .name, .lamp, .map-place';
const GAP = 12;               // the label's distance from the box, as .scan-chip's CSS draws it

function overlap(a, b) {
  const w = Math.min(a.right, b.right) - Math.max(a.left, b.left);
  const h = Math.min(a.bottom, b.bottom) - Math.max(a.top, b.top);
  return w > 0 && h > 0 ? w * h : 0;
}

// Where the label goes round the box: above or below it (from its near or far edge), or beside
// it. The place that covers least of what matters and stays in the window wins; ties go to the
// first: above, on the box's near side.
function chipPlace(b, inside) {
  const vw = document.documentElement.clientWidth, vh = window.innerHeight;
  const box = { left: b.left - window.scrollX, top: b.top - window.scrollY };
  box.right = box.left + b.width;
  box.bottom = box.top + b.height;
  const w = chip.offsetWidth, h = chip.offsetHeight;
  const near = box.left + b.width / 2 > vw / 2 ? 'right' : 'left';
  const far = near === 'right' ? 'left' : 'right';
  const at = {
    'above-left': [box.left - GAP, box.top - GAP - h], 'above-right': [box.right + GAP - w, box.top - GAP - h],
    'below-left': [box.left - GAP, box.bottom + GAP], 'below-right': [box.right + GAP - w, box.bottom + GAP],
    right: [box.right + GAP, box.top], left: [box.left - GAP - w, box.top],
  };
  const order = [`above-${near}`, `above-${far}`, `below-${near}`, `below-${far}`, near, far];
  const others = [];
  for (const n of document.querySelectorAll(`${MATTERS}, ${ACTIONABLE}`)) {
    if (inside.some((i) => i === n || i.contains(n) || n.contains(i)) || n.closest('#scan-ring')) continue;
    const news = n.matches(MATTERS);
    if (news && !n.textContent.trim()) continue;      // an empty status line hides nothing
    // nor does what is not shown: Release all keeps its room under the stop, invisible
    if (!n.checkVisibility({ visibilityProperty: true })) continue;
    const r = n.getBoundingClientRect();
    if (r.width && r.height && r.bottom > 0 && r.top < vh) others.push({ r, weight: news ? 10 : 1 });
  }
  let best = null;
  for (const name of order) {
    const [left, top] = at[name];
    const r = { left, top, right: left + w, bottom: top + h };
    const off = (r.top < 0 || r.bottom > vh ? 1e9 : 0) + (r.left < 0 || r.right > vw ? 1e8 : 0);
    const cost = off + others.reduce((sum, o) => sum + o.weight * overlap(r, o.r), 0);
    if (!best || cost < best.cost) best = { cost, name };
  }
  return best.name;
}

let placed = '';              // the box and label the label's place was chosen for

function place() {
  if (!scan.entry) return;
  if (!scan.entry.nodes.every((n) => n.isConnected)) refresh();   // the page re-drew those controls
  if (!scan.entry) return;
  const b = boxOf(scan.entry);
  // Keep the ring (drawn up to 12 px outside the box) inside the page: no sideways scrolling.
  const edge = 13, right = document.documentElement.clientWidth + window.scrollX - edge;
  if (b.left < edge) { b.width -= edge - b.left; b.left = edge; }
  if (b.left + b.width > right) b.width = right - b.left;
  Object.assign(ring.style, { left: `${b.left}px`, top: `${b.top}px`, width: `${b.width}px`, height: `${b.height}px` });
  const key = [b.left, b.top, b.width, b.height, window.scrollX, window.scrollY, chip.textContent, chip.offsetWidth].join();
  if (key === placed) return;    // called every frame: choose again only when something moved
  placed = key;
  ring.dataset.chip = chipPlace(b, scan.entry.box ? [scan.entry.box] : scan.entry.nodes);
}

function loop() {
  if (!scan.running) return;
  follow();
  place();
  requestAnimationFrame(loop);
}

// A page that drew its controls again under the ring (a step's description that came late)
// leaves the ring, and every opened row or group, on nodes that are gone: a select would act on
// nothing, and an opened row would hold only Back. Find each again among the new controls by
// its words; one that is gone closes, and the ring goes on at the level above.
function follow() {
  const gone = (entry) => entry && !entry.nodes.every((n) => n.isConnected);
  if (!gone(scan.entry) && !scan.levels.some((lv) => gone(lv.entry))) return;
  for (let i = 1; i < scan.levels.length; i += 1) {
    const lv = scan.levels[i];
    if (!gone(lv.entry)) continue;
    const again = scan.levels[i - 1].build().find((e) => e.label === lv.entry.label && e.open);
    if (!again) { scan.levels.length = i; break; }
    lv.entry = again;
    lv.build = withBack(again);
  }
  const label = scan.entry && scan.entry.label;
  const same = level().build().findIndex((e) => e.label === label);
  if (same >= 0) level().index = same;
  refresh();
}

// --- sound: a short beep per move, a higher one per select (WebAudio, made at the first press) --
let audio = null;
function unlockAudio() {
  if (!settings().sound) return;
  if (!audio) audio = new AudioContext();
  if (audio.state === 'suspended') audio.resume();
}
function beep(hz, ms) {
  if (!settings().sound || !audio) return;
  const t = audio.currentTime;
  const osc = audio.createOscillator();
  const gain = audio.createGain();
  osc.frequency.value = hz;
  gain.gain.setValueAtTime(0.2, t);
  gain.gain.exponentialRampToValueAtTime(0.001, t + ms / 1000);
  osc.connect(gain).connect(audio.destination);
  osc.start(t);
  osc.stop(t + ms / 1000);
}

// --- the controller ----------------------------------------------------------------------------
const scan = {
  running: false,
  levels: [],       // [{ build() -> entries, index, steps }]: the top level and what was opened
  entry: null,      // the entry ringed now
  latched: null,    // stop() of a control started by a select, stopped by the next press
  press: null,      // the switch press being held: { which, consumed, timer }
  timer: null,      // automatic scanning's next move
  suspended: 0,     // the Access page is listening for a new switch
  steps: 0,         // moves of the ring, as data-step (a test or a person's tool can follow it)
  lastTap: null,    // { which, at }: the last tap's release, for two quick taps = stop
  undo: null,       // { tab, label, levels }: the page shown and the ring before the last page change
  resumeFrom: null, // the control last selected, when the ring goes on from there (resumeAt)
};

function level() { return scan.levels[scan.levels.length - 1]; }

function mark(entry) {
  for (const n of document.querySelectorAll('[data-scanned]')) n.removeAttribute('data-scanned');
  scan.entry = entry;
  if (!entry) return;
  for (const n of entry.nodes) n.setAttribute('data-scanned', '');
  // What the ring stands on, for a test or a person's tool: a control, a row or group, or Back.
  ring.dataset.kind = entry.back ? 'back' : entry.undo ? 'undo' : entry.open ? 'group' : 'control';
  ring.dataset.label = entry.label;
  chip.textContent = scan.latched ? `${entry.label}: running. Press your switch to stop.` : entry.label;
  place();
}

// Re-read the entries of the level (the page may have changed) and ring the one at its index.
function refresh() {
  let entries = level().build();
  while (!entries.length && scan.levels.length > 1) { scan.levels.pop(); entries = level().build(); }
  const lv = level();
  lv.index = Math.min(lv.index, entries.length - 1);
  mark(entries[lv.index]);
  return entries;
}

function show() {
  refresh();
  const target = scan.entry && (scan.entry.box || scan.entry.nodes[0]);
  if (target) target.scrollIntoView({ block: 'nearest', inline: 'nearest' });
  place();      // where the page scrolled to: the label's place is chosen for what is on screen now
  scan.steps += 1;
  ring.dataset.step = String(scan.steps);
  ring.hidden = false;
  beep(660, 60);
  schedule();
}

function schedule() {
  clearTimeout(scan.timer);
  if (scan.running && !scan.latched && settings().mode === 'auto') scan.timer = setTimeout(next, settings().intervalMs);
}

// Start over at the top; in Home mode, inside the whole page, at the whole page's top (its
// first entry is the stop too).
function toTop() {
  scan.resumeFrom = null;
  const page = scan.levels.length > 1 && scan.levels[1].page ? { ...scan.levels[1], index: 0, steps: 0 } : null;
  scan.levels = [{ build: topEntries, index: 0, steps: 0 }];
  if (page && settings().scope === 'home') scan.levels.push(page);
}

function back() {
  scan.levels.pop();
  level().steps = 0;
  beep(990, 60);
  show();
}

function start() {
  scan.levels = [];
  toTop();
  // Home mode starts where the person's tasks and places are.
  if (settings().scope === 'home' && location.hash.slice(1) !== 'home' && location.hash) location.hash = 'home';
  scan.running = true;
  show();
  status();
  requestAnimationFrame(loop);
}

export function stop() {
  if (scan.latched) {   // scanning turned off while a hold-to-move runs: it stops too
    const stopIt = scan.latched;
    scan.latched = null;
    ring.classList.remove('latched');
    stopIt();
  }
  scan.running = false;
  clearTimeout(scan.timer);
  mark(null);
  ring.hidden = true;
  status();
}

function next() {
  follow();
  const lv = level();
  const n = level().build().length;
  lv.index = (lv.index + 1) % Math.max(n, 1);
  lv.steps += 1;
  if (lv.steps >= settings().rounds * n) {
    // Rounds without a select: a row or group closes; at the top, scanning waits for a press.
    if (scan.levels.length > 1) { scan.levels.pop(); level().steps = 0; }
    else { stop(); return; }
  }
  show();
}

function select() {
  follow();
  let entry = scan.entry;
  if (entry && entry.back) { back(); return; }
  if (entry && entry.undo) { undo(); return; }
  // Open a row or group; one that holds a single row or control opens straight into it.
  while (entry && entry.open) {
    const inside = entry.open();
    if (inside.length > 1 || entry.page) {
      scan.levels.push({ build: withBack(entry), entry, index: startOf(inside, Boolean(entry.list)), steps: 0, page: Boolean(entry.page) });
      beep(990, 60);
      show();
      return;
    }
    if (!inside.length) break;
    entry = inside[0];
  }
  if (entry) activate(entry.nodes[0]);
}

function afterSelect(selected = null) {
  const after = settings().afterSelect;
  if (after === 'stay') level().steps = 0;
  else {
    toTop();
    if (after === 'resume') scan.resumeFrom = selected;
  }
  show();
  status();
}

function ringedControl() { return scan.entry ? scan.entry.nodes[0] : null; }

function latch(stopIt) {
  scan.latched = stopIt;
  clearTimeout(scan.timer);
  ring.classList.add('latched');
  mark(scan.entry);
  status();
  return () => {
    if (scan.latched !== stopIt) return;
    scan.latched = null;
    ring.classList.remove('latched');
    if (scan.running) afterSelect(ringedControl());
  };
}

// A page chosen by mistake: show the page before again and put the ring back where it was, on
// the tab chosen, so one tap moves on to the neighbour that was meant.
function undo() {
  const { tab, levels } = scan.undo;
  scan.undo = null;
  tab.click();
  scan.levels = levels;
  level().steps = 0;
  beep(990, 60);
  show();
}

function shownTab() { return document.querySelector('#tabs [role="tab"][aria-selected="true"]'); }

function activate(node) {
  beep(990, 90);
  // A page change is the navigation a select can undo (the view follows the hash a moment later,
  // so it is told by the tab chosen, not by the page shown after).
  const before = shownTab();
  const pageChange = before && node.getAttribute('role') === 'tab' && node !== before;
  const levels = scan.levels.map((lv) => ({ ...lv }));
  scan.undo = null;      // only the last step can be undone
  if (chooseControl(node, latch) === 'latched') {
    if (!scan.latched && scan.running) afterSelect(node);    // the control acted and did not latch
    return;
  }
  if (pageChange) scan.undo = { tab: before, levels, label: `Undo: back to ${nameOf(before)}` };
  if (scan.running) afterSelect(node);    // the select may have turned scanning off
}

// --- switch presses ----------------------------------------------------------------------------
// The stop from anywhere: two quick taps, or (when the person chose it) one long hold. The ring
// starts over at the stop, so Release all is the next entry.
function stopEverything() {
  beep(440, 200);
  emergencyStop();
  if (!scan.running) return;
  toTop();
  show();
  status();
}

function onDown(which) {
  if (scan.press) return;    // one press at a time
  const s = settings();
  const now = performance.now();
  const press = { which, consumed: true, timer: null, stopTimer: null };
  scan.press = press;
  unlockAudio();
  if (s.holdStopMs) press.stopTimer = setTimeout(() => { press.consumed = true; stopEverything(); }, s.holdStopMs);
  const quick = scan.lastTap && scan.lastTap.which === which && now - scan.lastTap.at <= s.doubleTapMs;
  scan.lastTap = null;
  if (quick && s.doubleTapStop && scan.running && !scan.latched) { stopEverything(); return; }
  if (scan.latched) {
    const stopIt = scan.latched;
    scan.latched = null;
    ring.classList.remove('latched');
    stopIt();
    if (scan.running) afterSelect(ringedControl());   // the held control: a second hold is near
    return;
  }
  if (!scan.running) { start(); return; }
  if (s.switches === 2) {
    if (which === 'next') { next(); press.tap = true; } else select();
    return;
  }
  if (s.mode === 'auto') { select(); return; }
  press.consumed = false;
  press.timer = setTimeout(() => { press.consumed = true; select(); }, s.holdMs);
}

function onUp(which) {
  const press = scan.press;
  if (!press || press.which !== which) return;
  clearTimeout(press.timer);
  clearTimeout(press.stopTimer);
  scan.press = null;
  if (!press.consumed) { next(); press.tap = true; }
  // A tap (a move of the ring, never a select): a second one soon after is the stop.
  if (press.tap) scan.lastTap = { which, at: performance.now() };
}

function forgetPress() {
  if (scan.press) { clearTimeout(scan.press.timer); clearTimeout(scan.press.stopTimer); scan.press = null; }
  scan.lastTap = null;
}

function on() { return settings().enabled && !scan.suspended; }

function keyWhich(e) {
  if (e.ctrlKey || e.altKey || e.metaKey) return null;
  const s = settings();
  const code = e.code || e.key;
  if (s.next.kind === 'key' && s.next.code === code) return 'next';
  if (s.switches === 2 && s.select.kind === 'key' && s.select.code === code) return 'select';
  return null;
}

function buttonWhich(button) {
  const s = settings();
  if (s.next.kind === 'mouse' && s.next.button === button) return 'next';
  if (s.switches === 2 && s.select.kind === 'mouse' && s.select.button === button) return 'select';
  return null;
}

function swallow(e) { e.preventDefault(); e.stopImmediatePropagation(); }

// Capturing listeners on window run before any of the page's, so a switch press never also
// clicks, types or starts a hold-to-move.
function listen() {
  window.addEventListener('keydown', (e) => {
    const which = on() && keyWhich(e);
    if (!which) return;
    swallow(e);
    if (!e.repeat) onDown(which);
  }, true);
  window.addEventListener('keyup', (e) => {
    const which = on() && keyWhich(e);
    if (!which) return;
    swallow(e);
    onUp(which);
  }, true);
  window.addEventListener('pointerdown', (e) => {
    const which = on() && e.pointerType === 'mouse' && buttonWhich(e.button);
    if (!which) return;
    swallow(e);
    onDown(which);
  }, true);
  window.addEventListener('pointerup', (e) => {
    const which = on() && e.pointerType === 'mouse' && buttonWhich(e.button);
    if (!which) return;
    swallow(e);
    onUp(which);
  }, true);
  // The mouse events that follow a switch's button press must not click what is under the pointer.
  for (const type of ['mousedown', 'mouseup', 'click', 'auxclick', 'contextmenu']) {
    window.addEventListener(type, (e) => {
      const touch = e.sourceCapabilities && e.sourceCapabilities.firesTouchEvents;
      if (e.isTrusted && !touch && on() && buttonWhich(e.button)) swallow(e);
    }, true);
  }
  // A press whose release the page never sees (the window lost focus) is forgotten, not a tap.
  window.addEventListener('blur', forgetPress);
}

// --- "press your switch now" -------------------------------------------------------------------
function keyLabel(e) {
  if (e.key === ' ') return 'Space';
  return e.key.length === 1 ? e.key.toUpperCase() : e.key;
}

// Take the next key or mouse button pressed as a switch. A press on `cancel` (any pointer)
// cancels. Resolves with the switch, or null when cancelled; `stopListening()` ends it early.
export function captureSwitch(cancel) {
  let done;
  const result = new Promise((resolve) => { done = resolve; });
  forgetPress();
  scan.suspended += 1;
  let finished = false;
  const finish = (value) => {
    if (finished) return;
    finished = true;
    window.removeEventListener('keydown', onKey, true);
    window.removeEventListener('pointerdown', onPointer, true);
    window.removeEventListener('contextmenu', swallow, true);
    scan.suspended -= 1;
    done(value);
  };
  const onKey = (e) => {
    if (e.repeat) return;
    const code = e.code || e.key;
    if (e.key === 'Escape' || !/^[A-Za-z0-9]{1,40}$/.test(code)) return;   // Esc stays the emergency stop
    swallow(e);
    finish({ kind: 'key', code, label: keyLabel(e) });
  };
  const onPointer = (e) => {
    if (cancel.contains(e.target)) { swallow(e); finish(null); return; }
    if (e.pointerType !== 'mouse' || e.button > 4) return;
    swallow(e);
    finish({ kind: 'mouse', button: e.button, label: MOUSE_BUTTONS[e.button] });
  };
  window.addEventListener('keydown', onKey, true);
  window.addEventListener('pointerdown', onPointer, true);
  window.addEventListener('contextmenu', swallow, true);
  return { result, stopListening: () => finish(null) };
}

// --- status line and start-up ------------------------------------------------------------------
export function describe(s = settings()) {
  const how = s.switches === 2 ? `${s.next.label} moves on, ${s.select.label} selects`
    : s.mode === 'auto' ? `press ${s.next.label} to select` : `tap ${s.next.label} to move on, hold it to select`;
  // Two quick taps exist where a tap only moves the ring: one switch stepping, or the next switch of two.
  const taps = s.switches === 2 || s.mode === 'step';
  const stops = [s.doubleTapStop && taps ? `${s.switches === 2 ? s.next.label : 'tap it'} twice quickly` : '',
    s.holdStopMs ? `hold it ${s.holdStopMs / 1000} s` : ''].filter(Boolean);
  return stops.length ? `${how}; ${stops.join(' or ')} to stop every robot` : how;
}

function status() {
  const line = document.getElementById('scan-state');
  const s = settings();
  line.hidden = !s.enabled;
  if (!s.enabled) return;
  if (scan.latched) line.textContent = 'Switch scanning: running. Press your switch to stop it.';
  else if (scan.running) line.textContent = `Switch scanning: ${describe(s)}.`;
  else line.textContent = `Switch scanning is on: press ${s.next.label} to start.`;
}

export function startScanning() {
  document.body.append(ring);
  listen();
  let pattern = settings().pattern;
  onSettings((s) => {
    forgetPress();    // a press begun under the old settings (its release may be another key now)
    if (!s.enabled) stop();
    else if (scan.running && s.pattern !== pattern) { toTop(); show(); }
    else schedule();
    pattern = s.pattern;
    status();
  });
  status();
}
