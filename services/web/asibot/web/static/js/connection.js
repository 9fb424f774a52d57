// The Connection Manager, always on screen: the robots found on the bus (simulated and real side
// by side, as the seed's connectSim / connectReal), which one the page commands, and whether its
// driver and controller are alive, its emergency stop engaged, or a fault reported.
import { api, choose, connectedRobots, onChange, paths, state } from './api.js';
import { attempt, el } from './ui.js';

function lamp(text, cls, title) {
  return el('span', { class: `lamp ${cls}`, title }, text);
}

// Something that comes and goes in a card (STOPPED, Release, a fault) keeps its room while it is
// away: nothing in the bar moves when a robot stops or is released.
function when(on, node) {
  if (!on) { node.classList.add('away'); node.setAttribute('aria-hidden', 'true'); if (node.tagName === 'BUTTON') node.disabled = true; }
  return node;
}

function card(robot) {
  const chosen = robot.id === state.chosen;
  const engaged = robot.estop.engaged;
  const lamps = el('span', { class: 'lamps' },
    lamp('Driver', robot.driver ? 'on' : 'off', robot.driver ? 'driver alive' : 'driver not running'),
    lamp('Controller', robot.controller ? 'on' : 'off', robot.controller ? 'kinematics alive' : 'kinematics not running'),
    when(engaged, lamp('STOPPED', 'alarm', engaged ? robot.estop.reason : '')),
    robot.fault ? lamp('FAULT', 'alarm', robot.fault) : null);
  // Its room is kept beside Command: a Release that comes moves nothing and adds no line.
  const release = when(engaged, el('button', {
    type: 'button', class: 'release', 'aria-label': `Release emergency stop of ${robot.id}`,
    title: 'Release the emergency stop: nothing moves until you ask it to',
    onclick: () => attempt(() => api.post(paths.robot.release(robot.id)),
      `${robot.id}: emergency stop released. Nothing moves until you ask it to.`),
  }, 'Release'));
  const actions = [
    // The name holds the word on the button (WCAG 2.5.3, label in name) and the robot's id.
    el('button', {
      type: 'button', 'aria-pressed': chosen ? 'true' : 'false', 'aria-label': `${chosen ? 'Commanding' : 'Command'} ${robot.id}`,
      onclick: () => choose(robot.id),
    }, chosen ? 'Commanding' : 'Command'),
    release,
  ];
  if (robot.world) {
    // Simulation only: after a test run the can lies on the floor; one button puts it back.
    actions.push(el('button', {
      type: 'button', 'aria-label': `Put the ${robot.world} back: ${robot.id}`,
      onclick: () => attempt(() => api.post(paths.robot.resetWorld(robot.id)),
        `${robot.id}: the ${robot.world} is back as it started.`),
    }, `Put the ${robot.world} back`));
  }
  if (robot.fault) {
    actions.push(el('button', {
      type: 'button', 'aria-label': `Reset fault of ${robot.id}`,
      onclick: () => attempt(() => api.post(paths.robot.resetFault(robot.id)), `${robot.id}: fault cleared.`),
    }, 'Reset fault'));
  }
  // Two lines whatever comes and goes: who it is and its lamps, then what can be done with it.
  return el('div', { class: `robot-card${chosen ? ' chosen' : ''}`, dataset: { robot: robot.id } },
    el('div', { class: 'card-head' },
      el('span', { class: 'who' }, el('span', { class: 'name' }, robot.id),
        el('span', { class: 'kind' }, `${robot.simulated ? 'simulated' : 'real'} ${robot.arm || ''} ${robot.has_base ? '+ base' : ''}`)),
      lamps),
    el('div', { class: 'card-actions' }, actions));
}

export function mountConnection(root) {
  const render = () => {
    const robots = connectedRobots();
    if (!robots.length) {
      root.replaceChildren(el('p', { class: 'none' },
        state.feed === 'live' ? 'No robot found. Start the stack with `asibot up`.' : 'Waiting for the server…'));
      return;
    }
    root.replaceChildren(...robots.map(card));
  };
  let last = '';
  onChange(() => {
    // Re-render only when what the cards show changed (not at every joint state).
    const robots = [...state.robots.values()].map((r) =>
      [r.id, r.driver, r.controller, r.estop.engaged, r.estop.reason, r.fault, r.arm]);
    const key = JSON.stringify([state.chosen, state.feed, robots]);
    if (key !== last) { last = key; render(); }
  });
  render();
}

// A tab about `robot` while the page commands another (`commanded`, or none): which robot the tab
// is about, and the one button that commands it. The tab shows its controls once it is commanded.
export function offerToCommand(robot, what, commanded) {
  return el('section', { class: 'about-robot', 'aria-label': `About ${robot.id}` },
    el('p', { class: 'big' }, `This page is about ${robot.id}, ${what}.`),
    el('p', {}, commanded
      ? `The page commands ${commanded.id} now. Its controls here would move ${robot.id}: they are shown once you command it.`
      : `No robot is commanded yet. The controls here are shown once you command ${robot.id}.`),
    el('button', { type: 'button', class: 'primary', onclick: () => choose(robot.id) }, `Command ${robot.id}`));
}
