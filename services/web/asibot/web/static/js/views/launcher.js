// Launcher tab: one large button per task (the seed's "Multi-Modal Task Launcher"); the running
// task is shown with its output and a Stop button.
import { api, onMessage, paths, state } from '../api.js';
import { attemptOn, el, notify } from '../ui.js';
import { outputPanel, stopProgramButton } from './program.js';

export default {
  mount(root) {
    // The tasks are what this page is for: scanned row by row however many (never one block).
    const grid = el('div', { class: 'launcher', role: 'group', 'aria-label': 'Tasks', dataset: { scan: 'rows' } });
    const output = outputPanel();
    const refresh = async () => {
      const { tasks } = await api.get(paths.tasks);
      grid.replaceChildren(...(tasks.length ? tasks.map((t) => el('button', {
        type: 'button', class: 'task-button', 'aria-label': `Launch ${t.name}`,
        onclick: () => attemptOn(t.robot || state.chosen, async (robot) => {      // its own robot first
          output.clear();
          const status = await api.post(paths.launchTask(t.name), { robot });
          output.show(status);
          return status;
        }, `${t.name}: started.`),
      }, el('img', { src: paths.icon(t.icon), alt: '' }), t.name))
        : [el('p', { class: 'muted' }, 'No tasks yet: make one on the Assigner page (or start the wizard from Home).')]));
    };
    root.replaceChildren(
      el('section', { class: 'panel', 'aria-label': 'Launcher' }, el('h2', {}, 'Launch a task'), grid),
      el('section', { class: 'panel', 'aria-label': 'Running task' },
        el('h2', {}, 'Running task'), el('div', { class: 'row' }, stopProgramButton()), output.node));
    const off = onMessage((msg) => { if (msg.type === 'tasks') refresh(); });
    refresh().catch((e) => notify(e.message));
    return { unmount: () => { off(); output.unmount(); } };
  },
};
