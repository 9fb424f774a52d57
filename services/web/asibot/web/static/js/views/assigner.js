// Assigner tab: program + words + icon -> a task, the button the Launcher shows. The task being
// made (name, program, words, icon) is kept across tab switches and reloads (keep.js).
import { api, paths, state } from '../api.js';
import { kept, recall, remember, setKept } from '../keep.js';
import { attempt, confirmable, el, notify } from '../ui.js';

export default {
  mount(root) {
    const name = kept('assigner.name', el('input', { type: 'text', 'aria-label': 'Task name', 'aria-describedby': 'assigner-name-error',
      placeholder: 'for example: Give me the red can' }));
    // A missing name is said at the field, not in a banner far from it.
    const nameError = el('p', { id: 'assigner-name-error', class: 'field-error', role: 'alert', hidden: true });
    const nameIs = (problem) => {
      nameError.textContent = problem || '';
      nameError.hidden = !problem;
      if (problem) name.setAttribute('aria-invalid', 'true'); else name.removeAttribute('aria-invalid');
    };
    name.addEventListener('input', () => nameIs(null));
    let taskNames = [];
    let editing = null;     // the task whose Edit filled the form: saving it again replaces it without asking
    const program = kept('assigner.program', el('select', { 'aria-label': 'Program' }));
    // The robot the task runs on, whatever the page commands when it is launched (a tile, a
    // word or the bridge): the one commanded now, unless the carer chooses another.
    const robot = kept('assigner.robot', el('select', { 'aria-label': 'Runs on' }));
    const ANY = '';
    const robotOptions = (want) => {
      const ids = [...new Set([...state.robots.keys(), ...(want ? [want] : [])])].sort();
      robot.replaceChildren(...ids.map((id) => el('option', { value: id }, id)),
        el('option', { value: ANY }, 'whichever is commanded'));
      robot.value = want !== undefined && want !== null ? want : (state.chosen || ANY);
    };
    const words = el('div', { class: 'chips', role: 'group', 'aria-label': 'Words that launch it' });
    const icons = el('div', { class: 'icons', role: 'radiogroup', 'aria-label': 'Icon' });
    const tasks = el('ul', { class: 'points', 'aria-label': 'Tasks' });
    const upload = el('input', { type: 'file', accept: 'image/png,image/jpeg,image/gif,image/webp', 'aria-label': 'Upload an icon' });
    let icon = recall('assigner.icon');
    let chosenWords = new Set(recall('assigner.words', []));

    const pickIcon = (n) => {
      icon = n;
      remember('assigner.icon', n);
      for (const b of icons.querySelectorAll('button')) b.setAttribute('aria-checked', String(b.dataset.icon === n));
    };
    const toggleWord = (w, b) => {
      if (chosenWords.has(w)) chosenWords.delete(w); else chosenWords.add(w);
      remember('assigner.words', [...chosenWords]);
      b.setAttribute('aria-pressed', String(chosenWords.has(w)));
    };
    // A word that is not in the list yet is added here, and chosen, without going to the Speech
    // page (which is where one teaches the robot how the person says it).
    const newWord = kept('assigner.newWord', el('input', { type: 'text', 'aria-label': 'New word or phrase', placeholder: 'give me the red can' }));
    const addWord = () => attempt(async () => {
      const text = newWord.value.trim();
      if (!text) throw new Error('Type the word or phrase first.');
      const word = knownWords.includes(text) ? text : (await api.post(paths.words, { text })).word;
      chosenWords.add(word);
      remember('assigner.words', [...chosenWords]);
      setKept(newWord, '');
      await refresh();
      return word;
    }, (w) => `"${w}" chosen for this task.`);
    newWord.addEventListener('keydown', (e) => { if (e.key === 'Enter') addWord(); });
    let knownWords = [];
    const refresh = async () => {
      const [p, w, i, t] = await Promise.all([api.get(paths.programs), api.get(paths.words), api.get(paths.icons), api.get(paths.tasks)]);
      knownWords = w.words;
      const keep = program.value;
      program.replaceChildren(...p.programs.map((n) => el('option', { value: n }, n)));
      if (p.programs.includes(keep)) program.value = keep;
      else kept.restore(program);   // the program chosen before this tab was last shown
      words.replaceChildren(...(w.words.length ? w.words.map((x) => {
        const b = el('button', { type: 'button', 'aria-pressed': String(chosenWords.has(x)) }, x);
        b.addEventListener('click', () => toggleWord(x, b));
        return b;
      }) : [el('span', { class: 'muted' }, 'No words yet: add one below (a task also works by touch alone).')]));
      icons.replaceChildren(...i.icons.map((x) => el('button', {
        type: 'button', role: 'radio', 'aria-checked': String(x.name === icon),
        'aria-label': `Icon ${x.name.replace(/\.[a-z]+$/, '')}`, dataset: { icon: x.name }, onclick: () => pickIcon(x.name),
      }, el('img', { src: paths.icon(x.name), alt: '' }))));
      robotOptions(robot.options.length ? robot.value : recall('assigner.robot'));   // the robots live now
      taskNames = t.tasks.map((x) => x.name);
      tasks.replaceChildren(...(t.tasks.length ? t.tasks.map((x) => el('li', {},
        el('img', { src: paths.icon(x.icon), alt: '', width: '48', height: '48' }),
        el('span', { class: 'pname' }, x.name),
        el('span', { class: 'pvals' }, `${x.program}.py${x.robot ? ` on ${x.robot}` : ''}${x.words.length ? ` · "${x.words.join('", "')}"` : ''}`),
        el('button', {
          type: 'button', 'aria-label': `Edit ${x.name}`, onclick: () => {
            editing = x.name;
            setKept(name, x.name); setKept(program, x.program); robotOptions(x.robot); setKept(robot, x.robot);
            chosenWords = new Set(x.words);
            remember('assigner.words', [...chosenWords]); pickIcon(x.icon); refresh();
          },
        }, 'Edit'),
        // Deleting asks first, and can be undone from the notice that says it is gone.
        confirmable('Delete', { 'aria-label': `Delete task ${x.name}` }, () => attempt(async () => {
          await api.del(paths.task(x.name));
          await refresh();
          notify(`Task "${x.name}" deleted.`, 'info', {
            label: 'Undo', run: () => attempt(async () => {
              await api.put(paths.task(x.name), { program: x.program, words: x.words, icon: x.icon, robot: x.robot || null });
              await refresh();
            }, `Task "${x.name}" is back.`),
          });
        }), { ask: 'Sure? Touch again to delete' }))) : [el('li', { class: 'muted' }, 'No tasks yet.')]));
    };
    const save = () => {
      const typed = name.value.trim();
      if (!typed) {
        nameIs('Name the task first: the words on its button, such as "Give me the red can".');
        name.focus();
        return;
      }
      attempt(async () => {
        if (!icon) throw new Error('Choose an icon for the task.');
        const r = await api.put(paths.task(typed), { program: program.value, words: [...chosenWords], icon, robot: robot.value || null });
        editing = r.name;
        await refresh();
        return r;
      }, (r) => `Task "${r.name}" saved: it is on the Launcher${r.robot ? `, and runs on ${r.robot}` : ''}.`);
    };
    // Saving under the name of another task replaces it: the button asks first.
    const saveButton = confirmable('Save task', { class: 'primary big' }, save, {
      ask: 'A task has this name: touch again to replace it',
      needed: () => taskNames.includes(name.value.trim()) && editing !== name.value.trim(),
    });
    upload.addEventListener('change', () => attempt(async () => {
      const form = new FormData();
      form.append('file', upload.files[0]);
      const r = await api.post(paths.icons, form);
      upload.value = '';
      await refresh();
      pickIcon(r.name);
    }, 'Icon uploaded.'));
    root.replaceChildren(el('div', { class: 'columns' },
      el('section', { class: 'panel', 'aria-label': 'New task' },
        el('h2', {}, 'Make a task'),
        el('div', { class: 'row' }, el('label', {}, 'Task name ', name)), nameError,
        el('div', { class: 'row' }, el('label', {}, 'Program ', program)),
        el('div', { class: 'row' }, el('label', {}, 'Runs on ', robot)),
        el('h3', {}, 'Words that launch it'), words,
        el('div', { class: 'row' }, el('label', {}, 'New word ', newWord),
          el('button', { type: 'button', onclick: addWord }, 'Add and choose it')),
        el('h3', {}, 'Icon'), icons,
        el('div', { class: 'row' }, el('label', {}, 'Or upload an image: ', upload)),
        el('div', { class: 'row' }, saveButton)),
      el('section', { class: 'panel', 'aria-label': 'Tasks' }, el('h2', {}, 'Tasks'), tasks)));
    refresh().catch((e) => notify(e.message));
    return {};
  },
};
