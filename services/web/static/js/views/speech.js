// Speech tab: the words and phrases that launch tasks. Typing a word works now; recognising it
// from the microphone comes with the voice access of a later release.
import { api } from '../api.js';
import { attempt, el, notify } from '../ui.js';

export default {
  id: 'speech',
  title: 'Speech',
  mount(root) {
    const list = el('ul', { class: 'points', 'aria-label': 'Words and phrases' });
    const word = el('input', { type: 'text', 'aria-label': 'Word or phrase', placeholder: 'give me the red can', maxlength: '80' });
    const refresh = async () => {
      const { words } = await api.get('/api/words');
      list.replaceChildren(...(words.length ? words.map((w) => el('li', {},
        el('span', { class: 'pname' }, w),
        el('button', {
          type: 'button', class: 'danger', 'aria-label': `Delete ${w}`,
          onclick: () => attempt(async () => { await api.del(`/api/words/${encodeURIComponent(w)}`); await refresh(); }, `"${w}" deleted.`),
        }, 'Delete'))) : [el('li', { class: 'muted' }, 'No words yet.')]));
    };
    const add = () => attempt(async () => {
      const r = await api.post('/api/words', { text: word.value.trim() });
      word.value = '';
      await refresh();
      return r;
    }, (r) => `"${r.word}" recorded.`);
    word.addEventListener('keydown', (e) => { if (e.key === 'Enter') add(); });
    root.replaceChildren(el('section', { class: 'panel', 'aria-label': 'Speech' },
      el('h2', {}, 'Words and phrases'),
      el('p', {}, 'Type the word or phrase a person will say to launch a task. Give it to a task on the Assigner page.'),
      el('div', { class: 'row' }, word, el('button', { type: 'button', class: 'primary', onclick: add }, 'Record word')),
      list));
    refresh().catch((e) => notify(e.message));
    return {};
  },
};
