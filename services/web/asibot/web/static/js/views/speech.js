// Speech tab: the words and phrases that launch tasks, and the microphone: listen, say a
// task's word, and see what the voice service heard and did (it only listens for the words
// given to tasks, and for stop, yes and no). "Record by saying it" teaches the voice service how
// the user says a word: the next phrase said into the microphone becomes a pronunciation of it.
import { api, onMessage, paths, state } from '../api.js';
import { listening, onListening, startListening, stopListening } from '../microphone.js';
import { kept, setKept } from '../keep.js';
import { attempt, el, notify } from '../ui.js';

const HEARD_KEPT = 8;
const heard = [];   // newest first, kept while the page is open

function describe(h) {
  const said = h.text ? `“${h.text}”` : 'Something I do not know';
  const did = {
    launch: `started ${h.task}`, refused: `${h.task} refused: ${h.reason}`, ask: `asked about ${h.task}`,
    cancel: `${h.task || 'nothing'} canceled`, stop: 'every robot stopped', nothing: h.reason || 'nothing done',
  }[h.action] || h.action;
  const text = `${said}: ${did}`;
  return /[.!?]$/.test(text) ? text : `${text}.`;
}

const LISTEN_S = 8;
const MAX_SAYINGS = 3;   // the voice service keeps the three newest sayings of a word

// What the voice service made of a saying, in the user's words.
function describeLearned(r) {
  const again = { true: 'Heard it again: matches. ', false: `Heard it again: ${r.heard ? `sounded like “${r.heard}”` : 'no match'}; kept this saying too. ` }[r.matched] || '';
  return `${again}Learned: ${r.phones} (saying ${r.sayings.length} of ${MAX_SAYINGS}).`;
}

// One word of the list: its name, Record by saying it (Say it again), Forget how I say it, Delete;
// each button's name begins with what it shows, then names the word.
function wordRow(w, sayings, refresh) {
  const heard = el('span', { class: 'muted', role: 'status', 'aria-live': 'polite' },
    sayings.length ? `Learned: ${sayings[sayings.length - 1]} (${sayings.length} of ${MAX_SAYINGS} sayings).` : '');
  const record = el('button', {
    type: 'button', 'aria-label': `${sayings.length ? 'Say it again' : 'Record by saying it'}: ${w}`,
    onclick: () => attempt(async () => {
      record.disabled = true;
      try {
        if (!listening()) await startListening();
        heard.textContent = `Listening: say “${w}” now.`;
        const r = await api.post(paths.learnWord, { word: w, page: state.page, seconds: LISTEN_S });
        await refresh();
        return r;
      } catch (e) {
        heard.textContent = e.message;
        throw e;
      } finally { record.disabled = false; }
    }, (r) => `“${w}”: ${describeLearned(r)}`),
  }, sayings.length ? 'Say it again' : 'Record by saying it');
  const forget = sayings.length ? [el('button', {
    type: 'button', 'aria-label': `Forget how I say it: ${w}`,
    onclick: () => attempt(async () => { await api.post(paths.forgetWord, { text: w }); await refresh(); }, `How “${w}” is said is forgotten.`),
  }, 'Forget how I say it')] : [];
  const remove = el('button', {
    type: 'button', class: 'danger', 'aria-label': `Delete ${w}`,
    onclick: () => attempt(async () => { await api.del(paths.word(w)); await refresh(); }, `"${w}" deleted.`),
  }, 'Delete');
  return el('li', {}, el('span', { class: 'pname' }, w), record, ...forget, remove, heard);
}

function micPanel() {
  const button = el('button', { type: 'button', class: 'primary capture', 'aria-pressed': String(listening()) });
  const state = el('p', { role: 'status', class: 'big' });
  const list = el('ul', { class: 'events', 'aria-label': 'What was heard' });
  const show = (on, why) => {
    button.setAttribute('aria-pressed', String(on));
    button.textContent = on ? 'Stop listening' : 'Listen to the microphone';
    state.textContent = on ? 'Listening: say a task\'s word, or "stop".' : (why ? `Not listening: ${why}` : 'Not listening.');
  };
  const draw = () => list.replaceChildren(...(heard.length ? heard.map((h) => el('li', { class: `event ${h.action === 'nothing' ? '' : 'info'}` }, describe(h)))
    : [el('li', { class: 'muted' }, 'Nothing heard yet.')]));
  button.addEventListener('click', () => (listening() ? stopListening() : attempt(startListening)));
  const offListen = onListening(show);
  const offHeard = onMessage((msg) => {
    if (msg.type === 'heard') { heard.unshift(msg); heard.length = Math.min(heard.length, HEARD_KEPT); draw(); }
    if (msg.type === 'voice' && msg.level !== 'info') notify(msg.text);
  });
  show(listening(), '');
  draw();
  // Ask yes first: a task heard starts only after "yes" (the voice service keeps the choice).
  const askFirst = [[false, 'Start a task at once'], [true, 'Ask me "yes" first']].map(([confirm, label]) => el('button', {
    type: 'button', dataset: { confirm: String(confirm) }, disabled: true,
    onclick: () => attempt(async () => shownConfirm(await api.put(paths.voice, { confirm })),
      confirm ? 'A task heard now starts after you say "yes".' : 'A task heard now starts at once.'),
  }, label));
  const shownConfirm = (s) => askFirst.forEach((b) => { b.disabled = false; b.setAttribute('aria-pressed', String(b.dataset.confirm === String(s.confirm))); });
  const askNote = el('p', { class: 'muted' });
  api.get(paths.voice).then(shownConfirm).catch((e) => { askNote.textContent = e.message; });
  const panel = el('section', { class: 'panel', 'aria-label': 'Microphone' }, el('h2', {}, 'Microphone'),
    el('div', { class: 'row' }, button), state,
    el('div', { class: 'row setting', role: 'group', 'aria-label': 'When a task is heard' }, el('span', { class: 'label' }, 'When a task is heard'), askFirst),
    askNote, el('h3', {}, 'Heard'), list);
  return { panel, unmount: () => { offListen(); offHeard(); } };
}

export default {
  mount(root) {
    const list = el('ul', { class: 'points', 'aria-label': 'Words and phrases' });
    const word = kept('speech.word', el('input', { type: 'text', 'aria-label': 'Word or phrase', placeholder: 'give me the red can', maxlength: '80' }));
    const learnNote = el('p', { class: 'muted' });
    const refresh = async () => {
      const { words } = await api.get(paths.words);
      // without the voice service the words are still listed; only the learned sayings are missing
      const learned = await api.get(paths.learnedWords).then((r) => { learnNote.textContent = ''; return r; })
        .catch((e) => { learnNote.textContent = e.message; return { words: {}, phrases: {} }; });
      const sayings = (w) => learned.words[learned.phrases[w]] || [];
      list.replaceChildren(...(words.length ? words.map((w) => wordRow(w, sayings(w), refresh))
        : [el('li', { class: 'muted' }, 'No words yet.')]));
    };
    const add = () => attempt(async () => {
      const r = await api.post(paths.words, { text: word.value.trim() });
      setKept(word, '');
      await refresh();
      return r;
    }, (r) => `"${r.word}" added.`);
    word.addEventListener('keydown', (e) => { if (e.key === 'Enter') add(); });
    const mic = micPanel();
    root.replaceChildren(el('div', { class: 'columns' },
      el('section', { class: 'panel', 'aria-label': 'Speech' },
        el('h2', {}, 'Words and phrases'),
        el('p', {}, 'Type the word or phrase a person will say to launch a task, and press “Add word”. Give it to a task on the Assigner page; then press “Listen to the microphone” and say it to check that it is heard.'),
        el('p', {}, 'A name, a made-up word, or a word said in your own way: press “Record by saying it” beside it in the list and say it once or twice; the robot then listens for the way you say it.'),
        el('div', { class: 'row' }, word, el('button', { type: 'button', class: 'primary', onclick: add }, 'Add word')),
        list, learnNote),
      mic.panel));
    refresh().catch((e) => notify(e.message));
    return { unmount: mic.unmount };
  },
};
