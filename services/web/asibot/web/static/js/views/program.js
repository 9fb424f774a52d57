// Program tab: an IDE for the user's Python programs. CodeMirror 6 with Python highlighting; new
// programs from the template; point buttons that insert a point and a movl at the cursor; save
// (the previous version is kept), rename, delete, syntax check with line numbers; Run and Stop
// with the program's output live in the page.
import { EditorView, basicSetup, python, keymap } from '/static/vendor/codemirror.js';
import { api, onMessage, paths, state } from '../api.js';
import { loadPoints, onPointsChange } from '../points.js';
import { attempt, confirmable, el, notify } from '../ui.js';

let current = sessionStorage.getItem('asibot.program');  // the program open in the editor

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

export function outputPanel() {
  const out = el('div', { class: 'output', role: 'log', 'aria-label': 'Program output', 'aria-live': 'polite' });
  const status = el('p', { role: 'status', class: 'big' });
  const line = (stream, text) => {
    out.append(el('div', { class: stream === 'err' ? 'err' : '' }, text));
    while (out.childNodes.length > 500) out.firstChild.remove();
    out.scrollTop = out.scrollHeight;
  };
  const showStatus = (s) => {
    if (s.running) status.textContent = `${s.program} is running on ${s.robot}.`;
    else if (s.last) status.textContent = `${s.last.program}: ${s.last.reason}.`;
    else status.textContent = 'No program has run yet.';
  };
  const off = onMessage((msg) => {
    if (msg.type === 'output') line(msg.stream, msg.line);
    if (msg.type === 'run') showStatus(msg.status);
  });
  api.get(paths.run).then((s) => { out.replaceChildren(); s.output.forEach(([st, t]) => line(st, t)); showStatus(s); })
    .catch((e) => notify(e.message));
  const clear = () => out.replaceChildren();
  return { node: el('div', {}, status, out), clear, unmount: off };
}

export function stopProgramButton() {
  return el('button', { type: 'button', class: 'danger', onclick: () => attempt(() => api.post(paths.stopRun), 'Program stopped.') }, 'Stop');
}

export default {
  id: 'program',
  title: 'Program',
  mount(root) {
    const list = el('div', { class: 'chips', role: 'group', 'aria-label': 'Programs' });
    const newName = el('input', { type: 'text', 'aria-label': 'New program name', placeholder: 'give_me_the_can' });
    const title = el('h2', {}, 'No program open');
    const problems = el('div', { class: 'problems', role: 'status' });
    const versions = el('div', { class: 'chips', role: 'group', 'aria-label': 'Previous versions' });
    const pointButtons = el('div', { class: 'chips', role: 'group', 'aria-label': 'Insert a point' });
    const holder = el('div', { class: 'editor' });
    const output = outputPanel();
    let saved = '';

    const editor = new EditorView({
      parent: holder,
      doc: '',
      extensions: [basicSetup, python(),
        keymap.of([{ key: 'Mod-s', preventDefault: true, run: () => { save(); return true; } }]),
        EditorView.contentAttributes.of({ 'aria-label': 'Program text' })],
    });
    const text = () => editor.state.doc.toString();
    const setText = (t) => { editor.dispatch({ changes: { from: 0, to: editor.state.doc.length, insert: t } }); saved = t; };

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
    const refreshList = async () => {
      const { programs } = await api.get(paths.programs);
      list.replaceChildren(...(programs.length ? programs.map((name) => el('button', {
        type: 'button', 'aria-pressed': String(name === current), onclick: () => open(name),
      }, name)) : [el('span', { class: 'muted' }, 'No programs yet: type a name and touch New program.')]));
    };
    const open = (name) => attempt(async () => {
      const p = await api.get(paths.program(name));
      current = name;
      sessionStorage.setItem('asibot.program', name);
      title.textContent = `${name}.py`;
      setText(p.text);
      showProblems([]);
      versions.replaceChildren(...p.versions.slice(0, 8).map((v) => el('button', {
        type: 'button', title: `${v.size} bytes`,
        onclick: () => attempt(async () => {
          const r = await api.post(paths.restoreVersion(name, v.id));
          setText(r.text);
          await open(name);
        }, 'Previous version restored.'),
      }, `Restore ${new Date(v.saved * 1000).toLocaleTimeString()}`)));
      await refreshList();
    });
    const save = () => current && attempt(async () => {
      const r = await api.put(paths.program(current), { text: text() });
      saved = text();
      showProblems(r.problems);
      await open(current);
      return r;
    }, (r) => (r.problems.length ? 'Saved, but it has a syntax error: see below.' : `Saved ${current}.py.`));
    const create = () => attempt(async () => {
      const name = newName.value.trim();
      await api.post(paths.programs, { name });
      newName.value = '';
      await open(name);
    }, 'New program from the template.');
    const rename = () => {
      if (!current) return;
      const input = el('input', { type: 'text', value: current, 'aria-label': 'New name of the program' });
      const bar = el('div', { class: 'row' }, input,
        el('button', {
          type: 'button', class: 'primary', onclick: () => attempt(async () => {
            await api.post(paths.renameProgram(current), { name: input.value.trim() });
            bar.remove();
            await open(input.value.trim());
          }, 'Renamed.'),
        }, 'Save name'),
        el('button', { type: 'button', onclick: () => bar.remove() }, 'Cancel'));
      title.after(bar);
      input.focus();
    };
    const del = () => current && attempt(async () => {
      await api.del(paths.program(current));
      current = null; sessionStorage.removeItem('asibot.program');
      title.textContent = 'No program open'; setText('');
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
    const run = () => current && attempt(async () => {
      if (text() !== saved) await save();
      output.clear();
      return api.post(paths.runProgram(current), { robot: state.chosen, minutes: Number(minutes.value) });
    }, `Running ${current}.`);
    // A program that waits for ever is stopped at its time limit (the server's sandbox).
    const minutes = el('input', { type: 'number', id: 'run-minutes', min: '1', max: '240', value: '10', class: 'narrow' });

    root.replaceChildren(el('div', { class: 'columns' },
      el('div', {},
        el('section', { class: 'panel', 'aria-label': 'Programs' },
          el('h2', {}, 'Programs'), list,
          el('div', { class: 'row' }, newName, el('button', { type: 'button', class: 'primary', onclick: create }, 'New program'))),
        el('section', { class: 'panel', 'aria-label': 'Run' },
          el('h2', {}, 'Run'),
          el('div', { class: 'row' }, el('button', { type: 'button', class: 'primary big', onclick: run }, 'Run'), stopProgramButton(),
            el('label', { for: 'run-minutes' }, 'Time limit, minutes'), minutes),
          output.node)),
      el('section', { class: 'panel', 'aria-label': 'Editor' },
        title,
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
          confirmable('Delete', {}, del)),
        el('h3', {}, 'Insert a point (at the cursor: the point and a movl to it)'), pointButtons,
        holder, problems,
        el('h3', {}, 'Previous versions'), versions)));
    refreshList().catch((e) => notify(e.message));
    loadPoints().catch((e) => notify(e.message));
    if (current) open(current);
    return { unmount: () => { offPoints(); output.unmount(); editor.destroy(); } };
  },
};
