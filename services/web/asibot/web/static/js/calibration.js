// The camera calibration walk-through: where a camera stands, measured by touching marks with
// the tool. Each round: touch a mark in the camera's picture, jog the fingertips onto it, and
// say "The tool is on the mark"; after three or more marks (not in a line) "Solve" gives the
// camera's pose and how well the marks agree (the residual, mm). The server keeps the pose and
// uses it from then on (services/web/asibot/web/world.py); "Start again" forgets it.
import { api, paths, state } from './api.js';
import { attemptOn, el } from './ui.js';

export function calibrationPanel(camera, onChange = () => {}) {
  let spot = null;
  let count = 0;
  const status = el('p', { class: 'calibration-status', role: 'status' });
  const result = el('p', { class: 'calibration-result', role: 'status' });
  const at = (path) => path(state.chosen, camera());
  const say = () => {
    const marks = `${count} mark${count === 1 ? '' : 's'} so far${count < 3 ? `; at least 3 are needed` : ''}.`;
    status.textContent = spot ? `Mark chosen (the cross-hair). Jog the fingertips onto it, then touch "The tool is on the mark". ${marks}`
      : `Touch a mark in the picture. ${marks}`;
  };
  const load = () => attemptOn(state.chosen, async () => {
    const c = await api.get(at(paths.robot.calibration));
    count = c.marks.length;
    result.textContent = c.pose ? `In use: the pose solved from ${count} marks, residual ${c.residual_mm} mm.` : '';
    say();
  });
  const onMark = el('button', {
    type: 'button', class: 'primary',
    onclick: () => {
      if (!spot) { status.textContent = 'First touch the mark in the picture (or Pick a spot and select it).'; return; }
      attemptOn(state.chosen, async () => {
        const c = await api.post(at(paths.robot.calibrationMarks));
        count = c.marks.length;
        spot = null;
        say();
      });
    },
  }, 'The tool is on the mark');
  const useIt = el('button', { type: 'button', class: 'primary', hidden: true, onclick: () => { close(); } }, 'Use it');
  const solve = el('button', {
    type: 'button',
    onclick: () => attemptOn(state.chosen, async () => {
      const c = await api.post(at(paths.robot.calibrationSolve));
      result.textContent = `Solved from ${c.marks.length} marks: the marks are ${c.residual_mm} mm from where this pose puts them, on average. `
        + 'The camera uses this pose now.';
      useIt.hidden = false;
      onChange();
    }),
  }, 'Solve');
  const again = el('button', {
    type: 'button', class: 'danger',
    onclick: () => attemptOn(state.chosen, async () => {
      await api.del(at(paths.robot.calibration));
      count = 0; spot = null; result.textContent = ''; useIt.hidden = true;
      say();
      onChange();
    }),
  }, 'Start again');
  const root = el('div', { class: 'calibration', role: 'region', 'aria-label': 'Calibrate the camera', hidden: true },
    el('h3', {}, 'Calibrate the camera'),
    el('ol', {},
      el('li', {}, 'Touch a mark in the picture: a spot the fingertips can touch (a sticker, a corner of the counter).'),
      el('li', {}, 'Jog the tool until its fingertips touch the mark.'),
      el('li', {}, 'Touch "The tool is on the mark". Do this for 3 or more marks, spread out, not in one line.'),
      el('li', {}, 'Touch Solve.')),
    status, el('div', { class: 'row' }, onMark, solve, useIt, again,
      el('button', { type: 'button', onclick: () => close() }, 'Close')),
    result);
  const close = () => { root.hidden = true; spot = null; onChange(); };
  return {
    root,
    get open() { return !root.hidden; },
    show() { root.hidden = false; useIt.hidden = true; load(); },
    close,
    // The camera reads the mark now, while it is in view: the fingertips will hide it.
    spot(u, v) {
      attemptOn(state.chosen, async () => {
        await api.post(at(paths.robot.calibrationSpot), { u, v });
        spot = [u, v];
        say();
      });
    },
  };
}
