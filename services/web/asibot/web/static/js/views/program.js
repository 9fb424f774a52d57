// Program tab: an IDE for the user's Python programs. CodeMirror 6 with Python highlighting; new
// programs from the template; point buttons that insert a point and a movl at the cursor; save
// (the previous version is kept), rename, delete, syntax check with line numbers; Run and Stop
// with the program's output live in the page, and the run's state as the server tells it.
// Unsaved text is a draft, kept per program in this browser until it is saved or discarded: a
// tab switch, another program opened or a reload loses nothing.
import { EditorView, basicSetup, python, keymap } from '/static/vendor/codemirror.js';
import { api, onChange, onMessage, paths, state } from '../api.js';
import { kept, setKept } from '../keep.js';
import { loadPoints, onPointsChange } from '../points.js';
import { about, attempt, attemptOn, confirmable, el, notify } from '../ui.js';

let current = sessionStorage.getItem('asibot.program');  // the program open in the editor

// Drafts: { text, base } per program name, `base` the saved text the edits began from.
const DRAFT = 'asibot.draft.';
const drafts = {
  get(name) {
    try {
      const d = JSON.parse(localStorage.getItem(DRAFT + name));
      return d && typeof d.text === 'string' && typeof d.base === 'string' ? d : null;
    } catch (e) {
      return null;
    }
  },
  put(name, text, base) { localStorage.setItem(DRAFT + name, JSON.stringify({ text, base })); },
  drop(name) { localStorage.removeItem(DRAFT + name); },
  move(from, to) {
    const d = drafts.get(from);
    drafts.drop(from);
    if (d) drafts.put(to, d.text, d.base);
  },
};

const clock = (seconds) => new Date(seconds * 1000).toLocaleTimeString();

// A Python name for a point: "point-1" -> "point_1".
function variable(name) {
  const v = name.replace(/[^A-Za-z0-9_]/g, '_');
  return /^[0-9]/.test(v) ? `p_${v}` : v;
}

// The program's CartesianClient variable (the template's is simCart).
function clientName(text) {
  const m = text.match(/^\s*([A-Za-z_]\w*)\s*=\s*CartesianClient\(/m);
  return m ? m[1] : 'simCart';
}

// The running (or last) program's state and output, as the server has them: GET /api/run when
// shown and after a lost connection, then the feed's `run` messages (a run started, a run ended,
// however it was launched) and its `output` lines.
export function outputPanel() {
  const out = el('div', { class: 'output', role: 'log', 'aria-label': 'Program output', 'aria-live': 'polite' });
  const status = el('p', { role: 'status', class: 'big run-status' });
  let shownRun = null;   // `started` of the run whose output is shown
  const line = (stream, text) => {
    out.append(el('div', { class: stream === 'err' ? 'err' : '' }, text));
    while (out.childNodes.length > 500) out.firstChild.remove();
    out.scrollTop = out.scrollHeight;
  };
  const show = (s) => {
    if (s.running && s.started !== shownRun) { shownRun = s.started; out.replaceChildren(); }   // a new run
    if (s.running) status.textContent = `${s.program} is running on ${s.robot} (started ${clock(s.started)}).`;
    else if (s.last) status.textContent = `${about(s.last.robot, `${s.last.program}: ${s.last.reason}.`)} Ended ${clock(s.last.ended)}.`;
    else status.textContent = 'No program has run yet.';
  };
  const reload = () => api.get(paths.run).then((s) => {
    shownRun = s.started;
    out.replaceChildren();
    s.output.forEach(([st, t]) => line(st, t));
    show(s);
  }).catch((e) => notify(e.message));
  const off = onMessage((msg) => {
    if (msg.type === 'output') line(msg.stream, msg.line);
    if (msg.type === 'run') show(msg.status);
  });
  // Back after a lost connection: what happened meanwhile is only on the server.
  const offFeed = onChange((what) => { if (what === 'feed' && state.feed === 'live') reload(); });
  reload();
  const clear = () => out.replaceChildren();
  return { node: el('div', {}, status, out), clear, show, unmount: () => { off(); offFeed(); } };
}

export function stopProgramButton() {
  return el('button', { type: 'button', class: 'danger', onclick: () => attempt(() => api.post(paths.stopRun), 'Program stopped.') }, 'Stop');
}

export default {
  id: 'program',
  title: 'Program',
  mount(root) {
    const list = el('div', { class: 'chips', role: 'group', 'aria-label': 'Programs' });
    const newName = kept('program.new', el('input', { type: 'text', 'aria-label': 'New program name', placeholder: 'give_me_the_can' }));
    const title = el('h2', {}, 'No program open');
    const draftState = el('p', { class: 'draft-state', role: 'status' });
    const problems = el('div', { class: 'problems', role: 'status' });
    const versions = el('div', { class: 'chips', role: 'group', 'aria-label': 'Previous versions' });
    const pointButtons = el('div', { class: 'chips', role: 'group', 'aria-label': 'Insert a point' });
    const holder = el('div', { class: 'editor' });
    const output = outputPanel();
    let saved = '';      // the open program's text on the server
    let base = null;     // the saved text its draft began from (null: no draft)

    const text = () => editor.state.doc.toString();
    const unsaved = () => current !== null && text() !== saved;
    const showDraftState = () => {
      const changed = unsaved();
      const stale = changed && base !== null && base !== saved;
      draftState.className = `draft-state${changed ? ' unsaved' : ''}`;
      draftState.textContent = !current ? ''
        : !changed ? 'All changes saved.'
          : stale ? 'Unsaved changes (kept in this browser). The saved file changed since they began: Save writes them over it; Discard changes loads it.'
            : 'Unsaved changes (kept in this browser until you save or discard them).';
      discard.disabled = !changed;
      for (const b of list.querySelectorAll('button[data-program]')) if (b.dataset.program === current) markChip(b);
    };
    // Every edit is kept as the open program's draft; back to the saved text, no draft.
    const keepDraft = () => {
      if (!current) return;
      if (text() === saved) {
        drafts.drop(current);
        base = null;
      } else {
        if (base === null) base = saved;
        drafts.put(current, text(), base);
      }
      showDraftState();
    };
    const editor = new EditorView({
      parent: holder,
      doc: '',
      extensions: [basicSetup, python(),
        keymap.of([{ key: 'Mod-s', preventDefault: true, run: () => { save(); return true; } }]),
        EditorView.updateListener.of((u) => { if (u.docChanged) keepDraft(); }),
        EditorView.contentAttributes.of({ 'aria-label': 'Program text' })],
    });
    // Show `t`, with `savedText` the program's text on the server; the cursor stays when the
    // editor already shows `t`.
    const setText = (t, savedText) => {
      saved = savedText;
      if (t !== text()) editor.dispatch({ changes: { from: 0, to: editor.state.doc.length, insert: t } });
      else keepDraft();
    };

    const showProblems = (ps) => {
      problems.replaceChildren(...ps.map((p) => el('button', {
        type: 'button', class: 'danger',
        onclick: () => {
          const line = editor.state.doc.line(Math.min(p.line, editor.state.doc.lines));
          editor.dispatch({ selection: { anchor: line.from + Math.max(0, p.column - 1) }, scrollIntoView: true });
          editor.focus();
        },
      }, `Line ${p.line}: ${p.message}`)));
    };
    const markChip = (b) => {
      const name = b.dataset.program;
      const changed = name === current ? unsaved() : drafts.get(name) !== null;
      b.replaceChildren(name, changed ? el('span', { class: 'unsaved-mark' }, ' (unsaved)') : '');
    };
    const refreshList = async () => {
      const { programs } = await api.get(paths.programs);
      list.replaceChildren(...(programs.length ? programs.map((name) => {
        const b = el('button', { type: 'button', 'aria-pressed': String(name === current), dataset: { program: name }, onclick: () => open(name) });
        markChip(b);
        return b;
      }) : [el('span', { class: 'muted' }, 'No programs yet: type a name and touch New program.')]));
    };
    // Open `name`: its draft if it has one, else the saved text.
    const open = (name) => attempt(async () => {
      const p = await api.get(paths.program(name));
      current = name;
      sessionStorage.setItem('asibot.program', name);
      title.textContent = `${name}.py`;
      const draft = drafts.get(name);
      base = draft ? draft.base : null;
      setText(draft && draft.text !== p.text ? draft.text : p.text, p.text);
      showProblems([]);
      versions.replaceChildren(...p.versions.slice(0, 8).map((v) => confirmable(`Restore ${clock(v.saved)}`, {
        class: null, title: `${v.size} bytes`,
      }, () => attempt(async () => {
        await api.post(paths.restoreVersion(name, v.id));
        drafts.drop(name);
        await open(name);
      }, 'Previous version restored.'), { ask: 'Sure? Your unsaved changes go: touch again', needed: unsaved })));
      await refreshList();
    });
    const save = () => current && attempt(async () => {
      const name = current;
      const t = text();
      const r = await api.put(paths.program(name), { text: t });
      if (current === name) { saved = t; base = null; keepDraft(); }
      showProblems(r.problems);
      await open(name);
      return r;
    }, (r) => (r.problems.length ? 'Saved, but it has a syntax error: see below.' : `Saved ${current}.py.`));
    const discard = confirmable('Discard changes', { disabled: true, 'aria-label': 'Discard changes' }, () => {
      if (!current) return;
      drafts.drop(current);
      base = null;
      setText(saved, saved);
      notify(`${current}.py: back to the saved text.`, 'info');
    });
    const create = () => attempt(async () => {
      const name = newName.value.trim();
      await api.post(paths.programs, { name });
      setKept(newName, '');
      await open(name);
    }, 'New program from the template.');
    const rename = () => {
      if (!current) return;
      const input = el('input', { type: 'text', value: current, 'aria-label': 'New name of the program' });
      const bar = el('div', { class: 'row' }, input,
        el('button', {
          type: 'button', class: 'primary', onclick: () => attempt(async () => {
            const from = current;
            const to = input.value.trim();
            await api.post(paths.renameProgram(from), { name: to });
            drafts.move(from, to);
            bar.remove();
            await open(to);
          }, 'Renamed.'),
        }, 'Save name'),
        el('button', { type: 'button', onclick: () => bar.remove() }, 'Cancel'));
      // Esc cancels the new name; preventDefault tells the emergency stop's key that it did (estop.js).
      input.addEventListener('keydown', (e) => { if (e.key === 'Escape') { e.preventDefault(); bar.remove(); } });
      title.after(bar);
      input.focus();
    };
    const del = () => current && attempt(async () => {
      await api.del(paths.program(current));
      drafts.drop(current);
      current = null; sessionStorage.removeItem('asibot.program');
      title.textContent = 'No program open'; setText('', '');
      versions.replaceChildren();
      showDraftState();
      await refreshList();
    }, 'Program deleted (kept in the trash of the data folder).');
    const insertPoint = (p) => {
      const v = variable(p.name);
      const client = clientName(text());
      const values = p.values.map((x, i) => Number(x.toFixed(i < 3 ? 4 : 2))).join(', ');
      const snippet = `${v} = [${values}]\n${client}.movl(${v})\n${client}.wait()\n`;
      const at = editor.state.selection.main.head;
      const line = editor.state.doc.lineAt(at);
      const from = at === line.from ? at : line.to;
      const insert = at === line.from ? snippet : `\n${snippet}`;
      editor.dispatch({ changes: { from, insert }, selection: { anchor: from + insert.length } });
      editor.focus();
    };
    const offPoints = onPointsChange((data) => {
      pointButtons.replaceChildren(...(data.points.length ? data.points.map((p) => el('button', {
        type: 'button', 'aria-label': `Insert point ${p.name}`, onclick: () => insertPoint(p),
      }, p.name)) : [el('span', { class: 'muted' }, 'No points yet: capture some on the Joint or Cartesian page.')]));
    });
    const run = () => current && attemptOn(state.chosen, async (robot) => {
      if (unsaved()) await save();
      output.clear();
      const status = await api.post(paths.runProgram(current), { robot, minutes: Number(minutes.value) });
      output.show(status);
      return status;
    }, (s) => `Running ${s.program}.`);
    // A program that waits for ever is stopped at its time limit (the server's sandbox).
    const minutes = kept('program.minutes', el('input', { type: 'number', id: 'run-minutes', min: '1', max: '240', value: '10', class: 'narrow' }));

    root.replaceChildren(el('div', { class: 'columns' },
      el('div', {},
        el('section', { class: 'panel', 'aria-label': 'Programs' },
          el('h2', {}, 'Programs'), list,
          el('div', { class: 'row' }, newName, el('button', { type: 'button', class: 'primary', onclick: create }, 'New program'))),
        el('section', { class: 'panel', 'aria-label': 'Run' },
          el('h2', {}, 'Run'),
          el('div', { class: 'row' }, el('button', { type: 'button', class: 'primary big', onclick: run }, 'Run'), stopProgramButton(),
            el('label', { for: 'run-minutes' }, 'Time limit, minutes ', minutes)),
          output.node)),
      el('section', { class: 'panel', 'aria-label': 'Editor' },
        title, draftState,
        el('div', { class: 'row' },
          el('button', { type: 'button', class: 'primary', onclick: save, 'aria-keyshortcuts': 'Control+S' }, 'Save'),
          el('button', {
            type: 'button', onclick: () => attempt(async () => {
              const r = await api.post(paths.check, { text: text() });
              showProblems(r.problems);
              return r;
            }, (r) => (r.problems.length ? 'Syntax error: see below.' : 'No syntax errors.')),
          }, 'Check syntax'),
          el('button', { type: 'button', onclick: rename }, 'Rename'),
          discard,
          confirmable('Delete', {}, del)),
        el('h3', {}, 'Insert a point (at the cursor: the point and a movl to it)'), pointButtons,
        holder,
        el('p', { class: 'muted' }, 'Esc in the editor: the first only closes its list of completions or its search box (with nothing open, it only warns); the second is the emergency stop.'),
        problems,
        el('h3', {}, 'Previous versions'), versions)));
    showDraftState();
    refreshList().catch((e) => notify(e.message));
    loadPoints().catch((e) => notify(e.message));
    if (current) open(current);
    return { unmount: () => { offPoints(); output.unmount(); editor.destroy(); } };
  },
};
