// Program tab: an IDE for the user's Python programs. CodeMirror 6 with Python highlighting and
// the clients' methods as completions; new programs from the template; buttons that insert a
// gripper call, or a point and a movl, at the cursor; save (the previous version is kept),
// rename, delete, syntax check with line numbers; Run and Stop with the program's output live in
// the page, the run's state as the server tells it, a failed run as one sentence with its line
// (the traceback under Details); beside the editor, the clients' reference (pyhelp.js).
// Unsaved text is a draft, kept per program in this browser until it is saved or discarded: a
// tab switch, another program opened or a reload loses nothing.
// Below the list of programs: how much the programs keep of their limit (versions and trash
// included) and a control that empties the trash.
// Beside the Python editor, the steps editor (steps.js): a "Steps" / "Python" switch shows one or
// the other; a program made of steps opens in Steps, and one can be made straight from the
// "Pick it up" or "Put it down" template, or with no steps yet.
import { EditorView, basicSetup, python, keymap } from '/static/vendor/codemirror.js';
import { api, onChange, onMessage, paths, state } from '../api.js';
import { kept, setKept } from '../keep.js';
import { loadPoints, onPointsChange } from '../points.js';
import { completeClients, referencePanel } from '../pyhelp.js';
import { pointChooser, stepsEditor } from '../steps.js';
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
// Bytes as the server's sentences say them: 512 bytes, 12 KiB, 31.8 MiB.
const size = (n) => (n < 1024 ? `${n} bytes` : n < 1048576 ? `${Math.round(n / 1024)} KiB`
  : `${(n / 1048576).toFixed(1).replace(/\.0$/, '')} MiB`);

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

let detailsCount = 0;   // ids of the Details a panel shows

// The running (or last) program's state and output, as the server has them: GET /api/run when
// shown and after a lost connection, then the feed's `run` messages (a run started, a run ended,
// however it was launched) and its `output` lines. A run that ended in a Python error: its
// sentence ("Line 7: ..."), and its traceback under Details, which the server took out of the
// output. `lineButton(last)`: a control that shows that line (the Program tab's editor), or null.
// `confinement`: also say which walls programs run in here, or why they cannot run (docs/sandbox.md).
export function outputPanel({ lineButton = () => null, confinement = false } = {}) {
  const out = el('div', { class: 'output', role: 'log', 'aria-label': 'Program output', 'aria-live': 'polite' });
  const status = el('p', { role: 'status', class: 'big run-status' });
  const walls = el('p', { class: 'muted confinement', hidden: !confinement });
  const failure = el('div', { class: 'run-error', 'aria-live': 'polite', hidden: true });
  let shownRun = null;   // `started` of the run whose output is shown
  let shownEnd = null;   // the last run's end, as shown
  const line = (stream, text) => {
    out.append(el('div', { class: stream === 'err' ? 'err' : '' }, text));
    while (out.childNodes.length > 500) out.firstChild.remove();
    out.scrollTop = out.scrollHeight;
  };
  const showFailure = (last) => {
    shownEnd = last;
    if (!last || !last.error) { failure.hidden = true; failure.replaceChildren(); return; }
    const id = `run-details-${++detailsCount}`;
    const details = el('pre', { id, class: 'run-details', tabindex: '0', role: 'region', 'aria-label': 'Traceback', hidden: true }, last.details.join('\n'));
    const toggle = el('button', {
      type: 'button', 'aria-expanded': 'false', 'aria-controls': id,
      onclick: () => {
        details.hidden = !details.hidden;
        toggle.setAttribute('aria-expanded', String(!details.hidden));
      },
    }, 'Details');
    failure.replaceChildren(el('p', { class: 'run-error-sentence' }, last.error),
      el('div', { class: 'row' }, toggle, lineButton(last)), details);
    failure.hidden = false;
  };
  const show = (s) => {
    if (s.running && s.started !== shownRun) { shownRun = s.started; out.replaceChildren(); }   // a new run
    if (s.running) status.textContent = `${s.program} is running on ${s.robot} (started ${clock(s.started)}).`;
    else if (s.last && s.last.error) status.textContent = `${about(s.last.robot, `${s.last.program} failed.`)} Ended ${clock(s.last.ended)}.`;
    else if (s.last) status.textContent = `${about(s.last.robot, `${s.last.program}: ${s.last.reason}.`)} Ended ${clock(s.last.ended)}.`;
    else status.textContent = 'No program has run yet.';
    showFailure(s.running ? null : s.last);
  };
  const reload = () => api.get(paths.run).then((s) => {
    if (s.confinement) walls.textContent = s.confinement.text;
    shownRun = s.started;
    out.replaceChildren();
    s.output.forEach(([st, t]) => line(st, t));
    show(s);
  }).catch((e) => notify(e.message));
  const off = onMessage((msg) => {
    if (msg.type === 'output') line(msg.stream, msg.line);
    // An error's end: the output as the server keeps it, without the traceback it shows as details.
    if (msg.type === 'run' && !msg.status.running && msg.status.last && msg.status.last.error) reload();
    else if (msg.type === 'run') show(msg.status);
  });
  // Back after a lost connection: what happened meanwhile is only on the server.
  const offFeed = onChange((what) => { if (what === 'feed' && state.feed === 'live') reload(); });
  reload();
  const clear = () => out.replaceChildren();
  // Draw the failure again (the Program tab opened another program: its line button may change).
  const redraw = () => showFailure(shownEnd);
  return { node: el('div', {}, walls, status, failure, out), clear, show, redraw, unmount: () => { off(); offFeed(); } };
}

export function stopProgramButton() {
  return el('button', { type: 'button', class: 'danger', onclick: () => attempt(() => api.post(paths.stopRun), 'Program stopped.') }, 'Stop');
}

export default {
  mount(root) {
    const list = el('div', { class: 'chips', role: 'group', 'aria-label': 'Programs' });
    // How much the folder keeps (GET /api/storage), and the trash emptied (DELETE /api/trash).
    const storage = el('p', { class: 'muted storage', role: 'status' });
    const showStorage = (s) => {
      const items = s.trash_items === 1 ? '1 deleted item' : `${s.trash_items} deleted items`;
      storage.textContent = `Your programs use ${size(s.used)} of ${size(s.limit)} (versions ${size(s.versions)}, `
        + `trash ${size(s.trash)}: ${items}).`;
      emptyTrash.disabled = !s.trash_items;
    };
    // Disabled until the storage is known: a button that turns off under a Tab press is a trap.
    const emptyTrash = confirmable('Empty the trash', { disabled: true }, () => attempt(async () => {
      const r = await api.del(paths.trash);
      showStorage(r.storage);
      return r;
    }, (r) => `Trash emptied: ${size(r.freed)} freed.`), { ask: 'Sure? Deleted programs go for good: touch again' });
    const newName = kept('program.new', el('input', { type: 'text', 'aria-label': 'New program name', placeholder: 'give_me_the_can' }));
    const title = el('h2', {}, 'No program open');
    const draftState = el('p', { class: 'draft-state', role: 'status' });
    const problems = el('div', { class: 'problems', role: 'status' });
    const versions = el('div', { class: 'chips', role: 'group', 'aria-label': 'Previous versions' });
    const pointButtons = el('div', { class: 'chips', role: 'group', 'aria-label': 'Insert a point' });
    const holder = el('div', { class: 'editor' });
    const reference = referencePanel();
    // A failed run of the open program: a button that shows its line.
    const output = outputPanel({
      confinement: true,
      lineButton: (last) => (last.line && last.program === current ? el('button', {
        type: 'button', onclick: () => { setMode('python'); goToLine(last.line, 1); },
      }, `Show line ${last.line}`) : null),
    });
    let saved = '';      // the open program's text on the server
    let mode = 'python'; // the open program shown as 'steps' or 'python'
    const steps = stepsEditor({ onSaved: (name) => open(name), showPython: () => setMode('python') });
    const stepsPart = el('div', { hidden: true }, steps.node);
    const modeButtons = ['steps', 'python'].map((m) => el('button', {
      type: 'button', 'aria-pressed': 'false', dataset: { mode: m }, onclick: () => setMode(m),
    }, m === 'steps' ? 'Steps' : 'Python'));
    // A program made of steps, shown as Python: whether the Python is still the one they made.
    const syncNote = el('p', { class: 'steps-status out-of-sync', role: 'status', hidden: true });
    const fromSteps = el('div', { class: 'steps-chooser', role: 'group', 'aria-label': 'Choose a point', hidden: true });
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
    const py = python();
    const editor = new EditorView({
      parent: holder,
      doc: '',
      extensions: [basicSetup, py, py.language.data.of({ autocomplete: completeClients }),
        keymap.of([{ key: 'Mod-s', preventDefault: true, run: () => { save(); return true; } }]),
        EditorView.updateListener.of((u) => { if (u.docChanged) keepDraft(); }),
        // Long lines wrap: beside the stop's column, or on a tablet, the editor never scrolls
        // sideways (a sideways scroll a keyboard user cannot reach, and half a line hidden).
        EditorView.lineWrapping,
        EditorView.contentAttributes.of({ 'aria-label': 'Program text' })],
    });
    // Show `t`, with `savedText` the program's text on the server; the cursor stays when the
    // editor already shows `t`.
    const setText = (t, savedText) => {
      saved = savedText;
      if (t !== text()) editor.dispatch({ changes: { from: 0, to: editor.state.doc.length, insert: t } });
      else keepDraft();
    };

    // The cursor to `lineNo` (1-based), at `column`, in view.
    const goToLine = (lineNo, column) => {
      const line = editor.state.doc.line(Math.max(1, Math.min(lineNo, editor.state.doc.lines)));
      editor.dispatch({ selection: { anchor: Math.min(line.to, line.from + Math.max(0, column - 1)) }, scrollIntoView: true });
      editor.focus();
    };
    const showProblems = (ps) => {
      problems.replaceChildren(...ps.map((p) => el('button', {
        type: 'button', class: 'danger', onclick: () => goToLine(p.line, p.column),
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
      showStorage(await api.get(paths.storage));
    };
    // Open `name`: its draft if it has one, else the saved text.
    const open = (name) => attempt(async () => {
      const p = await api.get(paths.program(name));
      const s = await steps.open(name);
      current = name;
      sessionStorage.setItem('asibot.program', name);
      title.textContent = `${name}.py`;
      const draft = drafts.get(name);
      base = draft ? draft.base : null;
      setText(draft && draft.text !== p.text ? draft.text : p.text, p.text);
      reference.follow(text());
      setMode(sessionStorage.getItem(`asibot.program.mode.${name}`) || (s.steps !== null ? 'steps' : 'python'));
      syncNote.hidden = s.steps === null || s.in_sync;
      syncNote.textContent = 'This Python was edited after the program\'s steps made it: its steps no longer match it. '
        + 'Both are kept; the Steps view has the steps, and saving them there makes the Python from them again.';
      output.redraw();
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
    // Show the open program as steps or as Python (remembered per program in this browser tab).
    function setMode(m) {
      mode = m;
      if (current) sessionStorage.setItem(`asibot.program.mode.${current}`, m);
      stepsPart.hidden = m !== 'steps';
      pythonPart.hidden = m !== 'python';
      for (const b of modeButtons) b.setAttribute('aria-pressed', String(b.dataset.mode === m));
    }
    // A new program of steps: none yet, or a template's at a point; without a typed name it is
    // named after the template and the point ("pick_up_grasp-can").
    const createFromSteps = (template, point = null) => attempt(async () => {
      const typed = newName.value.trim();
      const { name } = await api.post(paths.stepPrograms, { name: typed || null, template, point });
      setKept(newName, '');
      sessionStorage.setItem(`asibot.program.mode.${name}`, 'steps');
      await open(name);
      steps.focusStart();     // keyboard, screen reader and switch go on from the new steps
      return name;
    }, (name) => `New program ${name}, made of steps.`);
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
      steps.close();
      syncNote.hidden = true;
      versions.replaceChildren();
      showDraftState();
      await refreshList();
    }, 'Program deleted (kept in the trash: Empty the trash, below the programs, removes it for good).');
    // `snippet` (whole lines) at the cursor: before its line when it is at the line's start, else after it.
    const insertLines = (snippet) => {
      const at = editor.state.selection.main.head;
      const line = editor.state.doc.lineAt(at);
      const from = at === line.from ? at : line.to;
      const insert = at === line.from ? snippet : `\n${snippet}`;
      editor.dispatch({ changes: { from, insert }, selection: { anchor: from + insert.length } });
      editor.focus();
    };
    const insertPoint = (p) => {
      const v = variable(p.name);
      const client = clientName(text());
      const values = p.values.map((x, i) => Number(x.toFixed(i < 3 ? 4 : 2))).join(', ');
      insertLines(`${v} = [${values}]\n${client}.movl(${v})\n${client}.wait()\n`);
    };
    // The gripper's action ("open" or "close"; CartesianClient.act), on the program's client.
    const insertGripper = (action) => insertLines(`${clientName(text())}.act("${action}")\n`);
    const gripperButtons = el('div', { class: 'chips', role: 'group', 'aria-label': 'Insert a gripper call' },
      el('button', { type: 'button', onclick: () => insertGripper('open') }, 'Insert: open gripper'),
      el('button', { type: 'button', onclick: () => insertGripper('close') }, 'Insert: close gripper'));
    const offPoints = onPointsChange((data) => {
      pointButtons.replaceChildren(...(data.points.length ? data.points.map((p) => el('button', {
        type: 'button', 'aria-label': `Insert point ${p.name}`, onclick: () => insertPoint(p),
      }, p.name)) : [el('span', { class: 'muted' }, 'No points yet: capture some on the Joint or Cartesian page.')]));
    });
    const run = () => current && attemptOn(state.chosen, async (robot) => {
      if (mode === 'steps' && steps.dirty()) {
        if (!steps.inSync()) throw new Error('Save the steps first: they replace the Python of the program, so Save steps asks you to confirm.');
        if (!(await steps.save())) throw new Error('The steps were not saved, so the program did not run.');
      } else if (mode === 'python' && unsaved()) await save();
      output.clear();
      const status = await api.post(paths.runProgram(current), { robot, minutes: Number(minutes.value) });
      output.show(status);
      return status;
    }, (s) => `Running ${s.program}.`);
    // A program that waits for ever is stopped at its time limit (the server's sandbox).
    const minutes = kept('program.minutes', el('input', { type: 'number', id: 'run-minutes', min: '1', max: '240', value: '10', class: 'narrow' }));

    const pythonPart = pythonPartOf();
    root.replaceChildren(el('div', { class: 'columns program-columns' },
      el('div', {},
        el('section', { class: 'panel', 'aria-label': 'Programs' },
          el('h2', {}, 'Programs'), list,
          el('div', { class: 'row' }, newName, el('button', { type: 'button', class: 'primary', onclick: create }, 'New program')),
          el('div', { class: 'row' },
            el('button', { type: 'button', onclick: () => createFromSteps('empty') }, 'New from steps'),
            el('button', { type: 'button', onclick: () => pointChooser(fromSteps, 'Pick it up at which point?', (p) => createFromSteps('pick_it_up', p)) }, 'New: Pick it up…'),
            el('button', { type: 'button', onclick: () => pointChooser(fromSteps, 'Put it down at which point?', (p) => createFromSteps('put_it_down', p)) }, 'New: Put it down…')),
          fromSteps,
          el('div', { class: 'row storage-row' }, storage, emptyTrash)),
        el('section', { class: 'panel', 'aria-label': 'Run' },
          el('h2', {}, 'Run'),
          el('div', { class: 'row' }, el('button', { type: 'button', class: 'primary big', onclick: run }, 'Run'), stopProgramButton(),
            el('label', { for: 'run-minutes' }, 'Time limit, minutes ', minutes)),
          output.node)),
      el('section', { class: 'panel', 'aria-label': 'Editor' },
        title,
        el('div', { class: 'row' },
          el('div', { class: 'row mode-switch', role: 'group', 'aria-label': 'Edit the program as' }, ...modeButtons),
          el('button', { type: 'button', onclick: rename }, 'Rename'),
          confirmable('Delete', {}, del)),
        stepsPart,
        pythonPart)));
    // The Python editor and what goes with it (hidden while the program is shown as steps).
    function pythonPartOf() {
      return el('div', {}, syncNote, draftState,
        el('div', { class: 'row' },
          el('button', { type: 'button', class: 'primary', onclick: save, 'aria-keyshortcuts': 'Control+S' }, 'Save'),
          el('button', {
            type: 'button', onclick: () => attempt(async () => {
              const r = await api.post(paths.check, { text: text() });
              showProblems(r.problems);
              return r;
            }, (r) => (r.problems.length ? 'Syntax error: see below.' : 'No syntax errors.')),
          }, 'Check syntax'),
          discard),
        el('h3', {}, 'Insert at the cursor (a gripper call, or a point and a movl to it)'),
        el('div', { class: 'row inserts' }, gripperButtons, pointButtons),
        el('div', { class: 'editor-beside' },
          el('div', {},
            holder,
            el('p', { class: 'muted' }, 'Esc in the editor: the first only closes its list of completions or its search box (with nothing open, it only warns); the second is the emergency stop.'),
            problems,
            el('h3', {}, 'Previous versions'), versions),
          reference.node));
    }
    showDraftState();
    refreshList().catch((e) => notify(e.message));
    loadPoints().catch((e) => notify(e.message));
    if (current) open(current);
    return { unmount: () => { offPoints(); steps.unmount(); output.unmount(); editor.destroy(); } };
  },
};
