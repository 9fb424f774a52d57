// Python help for the Program tab: the clients' reference as the server reads it from
// asibot.client (GET /api/client-reference: the docstrings are the one source, nothing of them is
// written here), the editor's completions of their methods after `<name>.`, and the reference
// panel beside the editor.
import { api, paths } from './api.js';
import { el } from './ui.js';

let reference = null;    // { module, clients: [{ name, doc, methods: [{ name, signature, call, returns, summary, doc }] }] }
let loading = null;

export function loadReference() {
  if (!loading) {
    loading = api.get(paths.clientReference).then((r) => { reference = r; return r; });
    loading.catch(() => { loading = null; });   // a later call asks again
  }
  return loading;
}

const NAME = '[A-Za-z_]\\w*';

// The names a program binds to a client: `robot = CartesianClient()`, `base: NavClient = NavClient.on(...)`,
// `with CartesianClient(robot_name) as robot:`. Map name -> the client's class name.
export function clientsIn(text, clients = reference ? reference.clients : []) {
  const found = new Map();
  if (!clients.length) return found;
  const classes = clients.map((c) => c.name).join('|');
  const assigned = new RegExp(`^\\s*(${NAME})\\s*(?::[^=\\n]*)?=\\s*(?:[\\w.]*\\.)?(${classes})\\s*[(.]`, 'gm');
  const opened = new RegExp(`\\b(${classes})\\s*\\([^)\\n]*\\)\\s+as\\s+(${NAME})`, 'g');
  for (const m of text.matchAll(assigned)) found.set(m[1], m[2]);
  for (const m of text.matchAll(opened)) found.set(m[2], m[1]);
  return found;
}

// The names a program imports (`import sys`, `import numpy as np`, `from os import path`).
function imported(text) {
  const names = new Set();
  const add = (list) => {
    for (const part of list.split(',')) {
      const words = part.trim().split(/\s+as\s+/);
      const name = (words[1] || words[0].split('.')[0]).trim();
      if (name) names.add(name);
    }
  };
  for (const m of text.matchAll(/^\s*import\s+([^\n#]+)/gm)) add(m[1]);
  for (const m of text.matchAll(/^\s*from\s+\S+\s+import\s+\(?([^)\n#]+)/gm)) add(m[1]);
  return names;
}

// `text` with its `code` parts as <code>.
function withCode(text) {
  return text.split('`').map((part, i) => (i % 2 ? el('code', {}, part) : part));
}

// CodeMirror completion source: after `<name>.` the methods of the client `name` holds, or of
// every client when the program does not say (a function's parameter, a name made elsewhere);
// nothing after an imported module, `self` or in a string or comment.
export function completeClients(context) {
  if (!reference) return null;
  const before = context.matchBefore(/[A-Za-z_]\w*\.\w*$/);
  if (!before || context.tokenBefore(['Comment', 'String', 'FormatString'])) return null;
  const name = before.text.slice(0, before.text.indexOf('.'));
  const text = context.state.doc.toString();
  const bound = clientsIn(text).get(name);
  if (!bound && (name === 'self' || name === 'cls' || imported(text).has(name))) return null;
  const seen = new Set();
  const options = [];
  for (const client of reference.clients.filter((c) => !bound || c.name === bound)) {
    for (const m of client.methods) {
      if (seen.has(m.name)) continue;
      seen.add(m.name);
      options.push({
        label: m.name,
        type: 'method',
        detail: m.call.slice(m.name.length),
        info: () => el('div', { class: 'completion-info' },
          el('code', {}, `${client.name}.${m.signature}`), el('p', {}, ...withCode(m.summary))),
      });
    }
  }
  return { from: before.from + name.length + 1, options, validFor: /^\w*$/ };
}

// The panel beside the editor: one client's methods at a time (the one the open program uses,
// or the one chosen), each with its call, what it returns and its docstring's first paragraph.
export function referencePanel() {
  const choice = el('div', { class: 'chips', role: 'group', 'aria-label': 'Client to show' });
  const about = el('p', { class: 'reference-about' });
  const list = el('dl', { class: 'methods' });
  // Scrolls by itself: focusable, so a keyboard can scroll it too.
  const body = el('div', { class: 'reference-body', tabindex: '0', role: 'region', 'aria-label': 'Methods' }, about, list);
  const intro = el('p', { class: 'muted' }, 'Loading the reference…');
  let shown = null;
  let chosen = false;    // the person chose a client: opening a program no longer changes it
  let program = '';      // the open program's text
  const used = () => clientsIn(program).values().next().value;   // the client it binds first

  const show = (name) => {
    const client = reference && reference.clients.find((c) => c.name === name);
    if (!client) return;
    shown = name;
    for (const b of choice.querySelectorAll('button')) b.setAttribute('aria-pressed', String(b.dataset.client === name));
    about.replaceChildren(...withCode(client.doc));
    list.replaceChildren(...client.methods.flatMap((m) => [
      el('dt', { id: `ref-${client.name}-${m.name}` }, el('code', {}, m.call + (m.returns ? ` -> ${m.returns}` : ''))),
      el('dd', {}, ...withCode(m.doc || 'No docstring.')),
    ]));
  };
  loadReference().then((r) => {
    intro.replaceChildren(`From the docstrings of ${r.module}. In the editor, a client's name and a dot offer these methods.`);
    choice.replaceChildren(...r.clients.map((c) => el('button', {
      type: 'button', 'aria-pressed': 'false', dataset: { client: c.name }, onclick: () => { chosen = true; show(c.name); },
    }, c.name)));
    show(used() || r.clients[0].name);
  }).catch((e) => { intro.textContent = `The reference could not be loaded: ${e.message}`; });

  return {
    node: el('section', { class: 'reference', 'aria-label': 'Python reference' },
      el('h3', {}, 'Python reference'), intro, choice, body),
    // Show the client the open program uses, unless the person chose one.
    follow(text) {
      program = text;
      const client = reference && !chosen && used();
      if (client && client !== shown) show(client);
    },
  };
}
