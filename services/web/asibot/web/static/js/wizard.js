// The Task Creator wizard, optional as on the seed: a progress bar over the steps Joint ->
// Cartesian -> Program -> Speech -> Assigner -> Launcher, a hint per step, and a way to jump to
// any step. It only guides: every page works the same with or without it.
import { el } from './ui.js';

const STEPS = [
  { tab: 'joint', title: 'Joint', hint: 'Move the arm joint by joint near the object. Touch Capture point when the arm is where it should go.' },
  { tab: 'cartesian', title: 'Cartesian', hint: 'Fine-tune the tool along x, y, z and capture the points of the task (above the object, at it, lifted).' },
  { tab: 'program', title: 'Program', hint: 'Write the program: type a name and touch New program, then touch the points under “Insert at the cursor” to add moves. Save, then Run to try it.' },
  { tab: 'speech', title: 'Speech', hint: 'Type the word or phrase that will launch the task, for example "give me the red can", and touch Add word.' },
  { tab: 'assigner', title: 'Assigner', hint: 'Make the task: choose the program, its words and an icon, then Save task.' },
  { tab: 'launcher', title: 'Launcher', hint: 'Touch the big button of your task to run it.' },
];

let current = sessionStorage.getItem('asibot.wizard');

export function startWizard() {
  current = '0';
  sessionStorage.setItem('asibot.wizard', current);
  go(0);
}

function stop() {
  current = null;
  sessionStorage.removeItem('asibot.wizard');
  render();
}

function go(i) {
  current = String(i);
  sessionStorage.setItem('asibot.wizard', current);
  location.hash = STEPS[i].tab;
  render();
}

export function render() {
  const box = document.getElementById('wizard');
  if (current === null) { box.hidden = true; return; }
  const i = Number(current);
  const step = STEPS[i];
  box.hidden = false;
  box.replaceChildren(
    el('div', { class: 'row' }, el('strong', {}, `Task Creator wizard: step ${i + 1} of ${STEPS.length}, ${step.title}`)),
    el('progress', { max: String(STEPS.length), value: String(i + 1), 'aria-label': 'Wizard progress' }),
    el('ol', { 'aria-label': 'Wizard steps' }, STEPS.map((s, k) => el('li', {},
      el('button', { type: 'button', 'aria-current': k === i ? 'step' : null, onclick: () => go(k) }, `${k + 1}. ${s.title}`)))),
    el('p', {}, step.hint),
    el('div', { class: 'row' },
      el('button', { type: 'button', disabled: i === 0, onclick: () => go(i - 1) }, 'Back'),
      i < STEPS.length - 1 ? el('button', { type: 'button', class: 'primary', onclick: () => go(i + 1) }, 'Next step') : null,
      el('button', { type: 'button', onclick: stop }, 'Close the wizard')));
}
