// Cartesian tab: jog the tool along x, y, z and its two rotations, move to (or by) a typed point
// with movj or movl as on the seed, open and close the gripper, capture points. The typed point
// is kept (keep.js) under `keep`: a tab switch or a reload does not reset it.
//
// Beside the jog controls, the robot's camera picture: touch what the arm should go to, and the
// page offers "Go above it" and "Reach it", each shown first as the orange ghost in the 3D view
// and moved only on "Move"; no coordinate is typed on that path (services/web/asibot/web/world.py).
import { api, chosenRobot, paths, state } from '../api.js';
import { calibrationPanel } from '../calibration.js';
import { CameraPicture } from '../camera.js';
import { gripperButtons, jogGrid, modeAndSpeed, stopButton } from '../jog.js';
import { kept, remember, setKept } from '../keep.js';
import { loadPoints, pointsPanel } from '../points.js';
import { attempt, attemptOn, el } from '../ui.js';
import { viewer } from '../viewer3d.js';

// The robot a panel commands, in its heading: " of asibot-sim".
export function robotLabel() {
  const label = el('span', { class: 'robot-label' });
  return { label, update: (robot) => { label.textContent = robot ? ` of ${robot.id}` : ''; } };
}

export function cartesianControls(keep = 'cartesian') {
  const axes = state.config.jog.point_axes;
  const rows = axes.map((a, i) => ({ label: a.name, unit: a.unit, digits: a.unit === 'm' ? 3 : 1, axis: i }));
  const jog = jogGrid('cartesian', rows, (r) => r.point);

  const inputs = rows.map((row, i) => kept(`${keep}.${i}`, el('input', {
    type: 'number', step: row.unit === 'm' ? '0.01' : '1', value: '0', 'aria-label': `${row.label} value, ${row.unit}`,
  })));
  const form = el('div', { class: 'form-grid' }, rows.map((row, i) => el('label', {}, `${row.label} (${row.unit})`, inputs[i])));
  const origin = kept(`${keep}.origin`, el('select', { 'aria-label': 'Origin' },
    el('option', { value: 'absolute' }, 'Absolute (base frame)'), el('option', { value: 'relative' }, 'Relative to the tool now')));
  const kind = kept(`${keep}.movement`, el('select', { 'aria-label': 'Movement' },
    el('option', { value: 'movj' }, 'movj: joints interpolated'), el('option', { value: 'movl' }, 'movl: straight line')));
  const values = () => inputs.map((x) => Number(x.value));
  const target = () => {
    const r = chosenRobot();
    if (origin.value === 'absolute' || !r || !r.point) return values();
    return values().map((v, i) => v + r.point[i]);
  };
  const showTarget = () => attemptOn(state.chosen, async (robot) => {
    const reply = await api.post(paths.robot.inverse(robot), { point: target() });
    viewer().showGhost(reply.names, reply.joints);
  });
  const fromArm = () => {
    const r = chosenRobot();
    if (r && r.point) { setKept(origin, 'absolute'); r.point.forEach((v, i) => { setKept(inputs[i], v.toFixed(i < 3 ? 3 : 1)); }); }
  };
  const robot = robotLabel();
  const panel = el('section', { class: 'panel jog-panel', 'aria-label': 'Cartesian jogging' },
    el('h2', {}, 'Move the tool', robot.label), modeAndSpeed(), jog.grid,
    el('div', { class: 'row' }, stopButton(), gripperButtons()),
    el('h3', {}, 'Move to a point'), form,
    el('div', { class: 'row' }, el('label', {}, 'Origin ', origin), el('label', {}, 'Movement ', kind)),
    el('div', { class: 'row' },
      el('button', {
        type: 'button', class: 'primary',
        onclick: () => attemptOn(state.chosen, (id) => api.post(paths.robot.move(id),
          { kind: kind.value, values: values(), relative: origin.value === 'relative' }), 'Moving.'),
      }, 'Move'),
      el('button', { type: 'button', onclick: showTarget }, 'Show target'),
      el('button', { type: 'button', onclick: fromArm }, 'Copy current point'),
      el('button', { type: 'button', onclick: () => viewer().showGhost(null) }, 'Hide target')));
  return { panel, update: (r) => { jog.update(r); robot.update(r); } };
}

// What a touch offers: "Go above it" (movj: the arm swings there) and "Reach it" (movl: a straight
// line down from above it into the grasp), each first as the ghost, then "Move".
const OFFERS = [
  { key: 'above', label: 'Go above it', kind: 'movj', moving: 'Moving above it.' },
  { key: 'reach', label: 'Reach it', kind: 'movl', moving: 'Reaching it in a straight line.' },
];

function touchResult(touched) {
  const box = el('div', { class: 'touch-result', role: 'region', 'aria-label': 'What you touched', dataset: { kind: touched.found.kind } });
  const confirm = el('div', { class: 'touch-confirm' });
  const chosen = { offer: null };
  const unreachable = OFFERS.filter((o) => touched[o.key].unreachable)
    .map((o) => el('p', { class: 'unreachable', role: 'status', dataset: { offer: o.key } }, `${o.label}: ${touched[o.key].unreachable}`));
  const preview = (offer) => {
    const candidate = touched[offer.key];
    chosen.offer = offer;
    if (!candidate.joints) {
      viewer().showGhost(null);
      confirm.replaceChildren(el('p', { class: 'unreachable', role: 'status' }, `${offer.label}: ${candidate.unreachable}`));
      return;
    }
    viewer().showGhost(touched.names, candidate.joints);
    confirm.replaceChildren(
      el('p', { role: 'status' }, `${offer.label}: the orange ghost in the 3D view shows the arm there. Touch Move to go.`),
      el('div', { class: 'row' },
        el('button', {
          type: 'button', class: 'primary', 'aria-label': `Move: ${offer.label}`,
          onclick: () => attemptOn(state.chosen, (id) => api.post(paths.robot.move(id), { kind: offer.kind, values: candidate.point }), offer.moving),
        }, 'Move'),
        el('button', { type: 'button', onclick: () => { viewer().showGhost(null); confirm.replaceChildren(); } }, 'Cancel')));
  };
  const name = el('input', { type: 'text', 'aria-label': 'Name of the kept point', placeholder: touched.name });
  const keepIt = el('button', {
    type: 'button',
    onclick: () => attempt(async () => {
      const body = { values: touched.reach.point };
      body.name = name.value.trim() || touched.name;
      const p = await api.post(paths.points, body);
      name.value = '';
      await loadPoints();
      return p;
    }, (p) => `Kept as ${p.name}: the grasp at what you touched.`),
  }, 'Keep as a point');
  // The shortest way from a touch to a task: remember what was touched (its colour and size,
  // and where it stood), make the "Pick it up" program of steps that looks for it when it runs,
  // and go on to the Assigner with that program chosen. A thing whose colour the camera cannot
  // tell is kept as a point, picked where it stands now.
  const thingName = () => name.value.trim() || (touched.colour ? `${touched.colour} object` : touched.name);
  // Taught again, a thing already picked up by a program: the question, here by the button
  // (update that program, so every task that runs it picks up what was touched now, or make
  // another), never a second program made behind the carer's back.
  const question = el('div', { class: 'ask-again', role: 'group', 'aria-label': 'Update or make another', hidden: true });
  const made = (program) => {
    question.hidden = true;
    if (program.replaced && program.tasks.length) return program;       // its tasks run it already
    remember('assigner.program', program.name);
    location.hash = 'assigner';
    return program;
  };
  const madeSays = (p) => (p.replaced
    ? `Updated ${p.name}: it picks up what you touched now${p.tasks.length ? `, and so does ${p.tasks.map((t) => `“${t}”`).join(', ')}` : ''}.`
    : `${p.name}: a program that picks it up, made of steps (see it on the Program page). Now name the task, give it words and an icon, and save it.`);
  const ask = (thing, sentence) => {
    const answer = (ifExists) => attempt(async () => made(await api.post(paths.stepPrograms, { template: 'pick_it_up', thing, if_exists: ifExists })), madeSays);
    question.replaceChildren(
      el('p', { role: 'status' }, sentence),
      el('div', { class: 'row' },
        el('button', { type: 'button', class: 'primary', onclick: () => answer('replace') }, 'Update it'),
        el('button', { type: 'button', onclick: () => answer('number') }, 'Make another'),
        el('button', { type: 'button', onclick: () => { question.hidden = true; } }, 'Cancel')));
    question.hidden = false;
    question.querySelector('button').focus();
  };
  const pickItUp = el('button', {
    type: 'button', class: 'primary', hidden: !touched.reach.joints,
    onclick: () => attempt(async () => {
      const found = touched.found;
      if (found.kind === 'object' && touched.colour) {
        const thing = { name: thingName(), colour: touched.colour, height: found.height, width: found.width, where: found.centre };
        try {
          return made(await api.post(paths.stepPrograms, { template: 'pick_it_up', thing, if_exists: 'ask' }));
        } catch (e) {
          if (e.code !== 'exists') throw e;
          ask(thing, e.message);
          return null;
        }
      }
      const body = { values: touched.reach.point };
      body.name = name.value.trim() || touched.name;
      const point = await api.post(paths.points, body);
      const program = await api.post(paths.stepPrograms, { template: 'pick_it_up', point: point.name });
      remember('assigner.program', program.name);
      location.hash = 'assigner';
      return program;
    }, (p) => (p ? madeSays(p) : null)),
  }, 'Pick it up: make a task');
  box.append(
    el('p', { class: 'touch-says' }, `You touched ${touched.says}.`),
    el('div', { class: 'row' }, OFFERS.map((o) => el('button', { type: 'button', dataset: { offer: o.key }, onclick: () => preview(o) }, o.label))),
    ...unreachable, confirm,
    el('div', { class: 'row' }, keepIt, el('label', {}, 'Name ', name)),
    el('div', { class: 'row' }, pickItUp), question);
  return box;
}

export function cameraPanel(onEnlarge) {
  const status = el('p', { class: 'muted camera-status', role: 'status' });
  const result = el('div', { class: 'touch-box' });
  let cameras = [];
  let shownFor = null;
  const camera = () => cameras.find((c) => c.picture) || null;
  const calibration = calibrationPanel(() => camera() && camera().name, () => refresh(true));
  const picture = new CameraPicture({
    onEnlarge,
    onSpot: (u, v) => {
      const cam = camera();
      if (!cam) return;
      if (calibration.open) { calibration.spot(u, v); return; }
      attemptOn(state.chosen, async (id) => {
        result.replaceChildren(el('p', { class: 'muted', role: 'status' }, 'Looking at what you touched…'));
        try {
          result.replaceChildren(touchResult(await api.post(paths.robot.touch(id, cam.name), { u, v })));
        } catch (e) {
          result.replaceChildren();
          throw e;
        }
      });
    },
  });
  const calibrate = el('button', { type: 'button', onclick: () => { result.replaceChildren(); calibration.show(); } }, 'Calibrate the camera');
  const heading = el('h2', {}, 'What the camera sees');
  const panel = el('section', { class: 'panel camera-panel', 'aria-label': 'Camera' },
    heading, status, picture.root, el('div', { class: 'row' }, calibrate), calibration.root, result);
  let timer = null;
  const refresh = async (again = false) => {
    const robot = state.chosen;
    if (!robot) { status.textContent = 'No robot commanded: press Command beside one in the Connection Manager first.'; picture.show(null, null); return; }
    if (!again && shownFor === robot && camera()) return;
    shownFor = robot;
    try {
      cameras = (await api.get(paths.robot.depthCameras(robot))).cameras;
    } catch (e) {
      cameras = [];
    }
    const cam = camera();
    picture.show(robot, cam);
    calibrate.hidden = !cam;
    if (!cam) status.textContent = `${robot} has no depth camera with a picture sending now; it shows here when one sends.`;
    else if (!cam.pose_from) status.textContent = `The ${cam.name} camera does not say where it stands: calibrate it before touching.`;
    else status.textContent = `Touch what the arm should go to (the ${cam.name} camera${cam.pose_from === 'calibration' ? ', calibrated' : ''}).`;
  };
  // Until a camera sends, look again now and then (the simulation may start after the page).
  timer = setInterval(() => { if (!camera() && !document.hidden) refresh(true); }, 3000);
  return {
    panel,
    update: () => { if (state.chosen !== shownFor) { result.replaceChildren(); refresh(); } },
    unmount: () => { clearInterval(timer); picture.stop(); },
  };
}

export default {
  mount(root) {
    const controls = cartesianControls();
    const points = pointsPanel();
    const columns = el('div', { class: 'columns world-columns' });
    const camera = cameraPanel((on) => columns.classList.toggle('camera-large', on));
    columns.append(controls.panel, camera.panel,
      el('div', { class: 'world-stack' }, el('section', { class: 'panel', 'aria-label': '3D view' }, viewer().root), points.panel));
    root.replaceChildren(columns);
    return {
      update: (r) => { controls.update(r); camera.update(r); },
      unmount: () => { points.unmount(); camera.unmount(); },
    };
  },
};
