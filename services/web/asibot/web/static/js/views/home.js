// Home tab: what this page is for, the robot it commands, and the Task Creator wizard.
import { api, chosenRobot, paths } from '../api.js';
import { attempt, el } from '../ui.js';
import { startWizard } from '../wizard.js';

export default {
  id: 'home',
  title: 'Home',
  mount(root) {
    const status = el('p', { class: 'big', role: 'status' });
    root.replaceChildren(
      el('section', { class: 'panel' },
        el('h2', {}, 'Teach the robot a task'),
        el('p', {}, 'Move the arm, capture the points it should visit, write a short program with them, ',
          'give it a word and an icon, and launch it from the Launcher with one touch.'),
        status,
        el('div', { class: 'row' },
          el('button', { type: 'button', class: 'primary big', onclick: startWizard }, 'Start the Task Creator wizard'),
          el('a', { href: '#launcher', class: 'button-link' }, 'Go to the Launcher'))),
      el('section', { class: 'panel' },
        el('h2', {}, 'Safety'),
        el('p', {}, 'The red Emergency stop button at the top, or the Esc key, stops every robot and the running program at once. ',
          'Release it in the Connection Manager; nothing moves again until you ask it to.'),
        el('p', { id: 'esc-rule' }, 'The Esc key: one Esc stops. In a text field or the program editor, or when Esc closes something ',
          '(the editor\'s list of completions, its search box, a name being changed), the first Esc only does that and the ',
          'button at the top says "Esc again: emergency stop"; the second Esc stops. So two Esc presses in a row always stop.')));
    const upload = el('input', { type: 'file', accept: '.zip,application/zip', 'aria-label': 'Import ASIBOT user files (a zip)' });
    const report = el('div', { role: 'status' });
    upload.addEventListener('change', () => attempt(async () => {
      const form = new FormData();
      form.append('file', upload.files[0]);
      const r = await api.post(paths.importFiles, form);
      upload.value = '';
      report.replaceChildren(
        el('p', {}, `Imported: ${r.imported.length ? r.imported.join(', ') : 'nothing'}.`),
        r.skipped.length ? el('p', {}, `Left out: ${r.skipped.map((s) => `${s.item} (${s.reason})`).join('; ')}.`) : null,
        ...r.notes.map((n) => el('p', { class: 'muted' }, n)));
      return r;
    }, (r) => `${r.imported.length} files imported.`));
    root.append(el('section', { class: 'panel', 'aria-label': 'Your files' },
      el('h2', {}, 'Your files'),
      el('p', {}, 'Points, programs, words, tasks and icons, in the formats of the original ASIBOT Task Creator ',
        '(points.ini, words.ini, <task>.task), so an existing user\'s files load.'),
      el('div', { class: 'row' },
        el('a', { href: paths.exportFiles, download: 'asibot-user-files.zip', class: 'button-link' }, 'Export my files'),
        el('label', {}, 'Import ASIBOT files: ', upload)),
      report));
    // A phone or a tablet: the address (and its QR code) when the page serves the LAN.
    const phone = el('section', { class: 'panel', 'aria-label': 'Phone or tablet' }, el('h2', {}, 'Use a phone or a tablet'));
    root.append(phone);
    api.get(paths.phone).then((p) => {
      phone.append(el('p', {}, p.text));
      if (!p.lan) return;
      phone.append(el('img', { class: 'qr', src: paths.phoneQr, width: '264', height: '264',
        alt: `QR code of the address ${p.urls[0]}` }));
      for (const url of p.urls) phone.append(el('p', { class: 'readout' }, url));
    }).catch((e) => phone.append(el('p', {}, `How to reach this page from a phone is not known: ${e.message}`)));
    const update = () => {
      const r = chosenRobot();
      status.textContent = r ? `Commanding ${r.id} (${r.simulated ? 'simulated' : 'real'} ${r.arm || 'robot'}).`
        : 'No robot commanded yet: press Command beside one in the Connection Manager at the top.';
    };
    return { update };
  },
};
