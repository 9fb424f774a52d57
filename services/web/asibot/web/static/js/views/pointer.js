// Pointer tab: the seed's Wii Remote today. A phone's tilt or a gamepad moves the arm's tip: the
// tool's pitch follows the device's pitch, the arm turns about its base with the device's roll,
// Forward and Back move along the tool; without them only the tool turns. Nothing moves without
// the dead-man, held or (the seed's users preferred it) toggled on and off.
//
// The page sends what the device reports, as it is; the server maps it (asibot.web.pointer), so
// no gain or unit lives here. The arm stops when the dead-man goes off, the device stops
// reporting for the server's silence time, the page loses focus or motion control is switched
// off (WCAG 2.5.4: Off is the default, and every motion has a button elsewhere).
import { chosenRobot, onMessage, sendLive, state } from '../api.js';
import { grip, gripperButtons } from '../jog.js';
import { about, el, fmt, notify } from '../ui.js';

const prefs = {
  get source() { return localStorage.getItem('asibot.pointer.source') || 'off'; },
  set source(v) { localStorage.setItem('asibot.pointer.source', v); },
  get deadman() { return localStorage.getItem('asibot.pointer.deadman') || 'hold'; },
  set deadman(v) { localStorage.setItem('asibot.pointer.deadman', v); },
};

const SOURCE_LABELS = { off: 'Off', phone: 'Phone tilt', gamepad: 'Gamepad' };
// The standard gamepad mapping: A is the dead-man, the right shoulder and trigger go forward, the
// left ones back, X closes the gripper and B opens it; the left stick tilts (up: nose up, right:
// turn right).
const PAD = { deadman: [0], forward: [5, 7], backward: [4, 6], open: [1], close: [2] };

function pressed(gamepad, indices) { return indices.some((i) => gamepad.buttons[i] && gamepad.buttons[i].pressed); }

function firstPad() {
  const pads = navigator.getGamepads ? [...navigator.getGamepads()] : [];
  return pads.find((p) => p && p.connected) || null;
}

export default {
  mount(root) {
    const cfg = state.config.pointer;
    const input = { forward: false, backward: false, deadman: false };   // the page's buttons (and the pad's dead-man)
    const pad = { forward: false, backward: false };                       // the gamepad's buttons
    let tilt = null;              // { pitch, roll, at } of the phone's last report
    let padDeadmanWas = false;    // the gamepad's dead-man button, last beat (for toggling)
    let padGripWas = null;        // the gamepad's open/close buttons, last beat (a press grips once)
    let streaming = false;
    let lastWhy = '';

    const status = el('p', { class: 'big', role: 'status' });
    const deviceReadout = el('p', { class: 'readout' }, '–');
    const toolReadout = el('p', { class: 'readout' }, '–');

    const stop = (why) => {
      if (streaming) sendLive({ type: 'release' });
      streaming = false;
      if (why && why !== lastWhy) notify(about(state.chosen, why), 'info');
      lastWhy = why || '';
    };
    const deadmanOff = (why) => {
      input.deadman = false;
      input.forward = false;
      input.backward = false;
      sync();
      stop(why);
    };

    // --- the source -----------------------------------------------------------------------
    const onTilt = (e) => {
      if (e.beta === null || e.gamma === null) return;   // a desktop without a sensor fires empty events
      tilt = { pitch: e.beta, roll: e.gamma, at: performance.now() };
    };
    const setSource = async (source) => {
      deadmanOff('');
      window.removeEventListener('deviceorientation', onTilt);
      tilt = null;
      if (source === 'phone') {
        // iOS asks the person first, and only from a tap (this click).
        if (typeof DeviceOrientationEvent !== 'undefined' && typeof DeviceOrientationEvent.requestPermission === 'function') {
          let answer = 'denied';
          try { answer = await DeviceOrientationEvent.requestPermission(); } catch (e) { answer = 'denied'; }
          if (answer !== 'granted') {
            notify('The phone did not allow this page to read its tilt; motion control stays off. Allow "Motion & Orientation Access" and choose Phone tilt again.');
            source = 'off';
          }
        }
        if (source === 'phone') window.addEventListener('deviceorientation', onTilt);
      }
      prefs.source = source;
      sync();
    };
    const sourceButtons = Object.entries(SOURCE_LABELS).map(([source, label]) => el('button', {
      type: 'button', dataset: { source }, onclick: () => setSource(source),
    }, label));
    const deadmanModes = [['hold', 'Hold the dead-man'], ['toggle', 'Tap the dead-man on and off']].map(([mode, label]) => el('button', {
      type: 'button', dataset: { mode },
      onclick: () => { prefs.deadman = mode; deadmanOff(''); },
    }, label));

    // --- the buttons ----------------------------------------------------------------------
    const deadman = el('button', { type: 'button', class: 'deadman', 'aria-pressed': 'false' }, 'Dead-man');
    const hold = (button, name) => {
      // A press acts at once (the next beat may be 60 ms away); a let-go stops at once.
      const on = () => { input[name] = true; sync(); beat(); };
      const off = () => { input[name] = false; sync(); beat(); };
      button.addEventListener('pointerdown', (e) => {
        if (e.button !== 0) return;
        e.preventDefault();
        button.setPointerCapture(e.pointerId);
        if (name === 'deadman' && prefs.deadman === 'toggle') { input.deadman = !input.deadman; sync(); beat(); return; }
        on();
      });
      for (const ev of ['pointerup', 'pointercancel', 'lostpointercapture']) {
        button.addEventListener(ev, () => { if (!(name === 'deadman' && prefs.deadman === 'toggle')) off(); });
      }
      button.addEventListener('keydown', (e) => {
        if ((e.key !== ' ' && e.key !== 'Enter') || e.repeat) return;
        e.preventDefault();
        if (name === 'deadman' && prefs.deadman === 'toggle') { input.deadman = !input.deadman; sync(); beat(); return; }
        on();
      });
      button.addEventListener('keyup', (e) => {
        if ((e.key === ' ' || e.key === 'Enter') && !(name === 'deadman' && prefs.deadman === 'toggle')) off();
      });
      // Switch scanning: a select turns it on, the switch's next press turns it off.
      button.addEventListener('scan:select', (e) => {
        e.preventDefault();
        on();
        e.detail.latch(off);
      });
    };
    const forward = el('button', { type: 'button', class: 'pointer-go', 'aria-pressed': 'false' }, 'Forward');
    const backward = el('button', { type: 'button', class: 'pointer-go', 'aria-pressed': 'false' }, 'Back');
    hold(deadman, 'deadman');
    hold(forward, 'forward');
    hold(backward, 'backward');

    function sync() {
      const source = prefs.source;
      sourceButtons.forEach((b) => b.setAttribute('aria-pressed', String(b.dataset.source === source)));
      deadmanModes.forEach((b) => b.setAttribute('aria-pressed', String(b.dataset.mode === prefs.deadman)));
      const off = source === 'off';
      for (const b of [deadman, forward, backward]) b.disabled = off;
      deadman.setAttribute('aria-pressed', String(input.deadman));
      deadman.textContent = prefs.deadman === 'toggle' ? `Dead-man: ${input.deadman ? 'on' : 'off'}` : 'Dead-man (hold)';
      const fwd = input.forward || pad.forward;
      const back = input.backward || pad.backward;
      forward.setAttribute('aria-pressed', String(fwd));
      backward.setAttribute('aria-pressed', String(back));
      status.textContent = off ? 'Motion control is off: tilting the phone or the gamepad moves nothing.'
        : !input.deadman ? 'Dead-man off: nothing moves.'
          : fwd === back ? 'Dead-man on: the tool turns with the device; press Forward or Back to move along it.'
            : fwd ? 'Moving forward along the tool; tilt to steer.'
              : 'Moving back along the tool; tilt to steer.';
    }

    // --- the beat ---------------------------------------------------------------------------
    const beat = () => {
      const source = prefs.source;
      let reading = null;
      if (source === 'phone') {
        if (tilt && performance.now() - tilt.at <= cfg.silence_ms) reading = { pitch: tilt.pitch, roll: tilt.roll };
        else if (streaming) deadmanOff('The phone stopped reporting its tilt: the arm stopped.');
      } else if (source === 'gamepad') {
        const gamepad = firstPad();
        if (!gamepad) {
          pad.forward = pad.backward = false;
          if (streaming || input.deadman) deadmanOff('The gamepad is gone: the arm stopped.');
        } else {
          reading = { pitch: -(gamepad.axes[1] || 0), roll: gamepad.axes[0] || 0 };
          const dm = pressed(gamepad, PAD.deadman);
          if (prefs.deadman === 'toggle') { if (dm && !padDeadmanWas) input.deadman = !input.deadman; } else if (dm !== padDeadmanWas) input.deadman = dm;
          padDeadmanWas = dm;
          pad.forward = pressed(gamepad, PAD.forward);
          pad.backward = pressed(gamepad, PAD.backward);
          const gripNow = pressed(gamepad, PAD.close) ? 'close' : pressed(gamepad, PAD.open) ? 'open' : null;
          if (gripNow && gripNow !== padGripWas && chosenRobot()) grip(gripNow === 'close');
          padGripWas = gripNow;
          sync();
        }
      }
      deviceReadout.textContent = reading
        ? (source === 'phone' ? `Phone: pitch ${fmt(reading.pitch, 0)}°, roll ${fmt(reading.roll, 0)}°`
          : `Gamepad stick: up ${fmt(reading.pitch, 2)}, right ${fmt(reading.roll, 2)}`)
        : source === 'off' ? 'No device in use.' : source === 'phone' ? 'Waiting for the phone to report its tilt…' : 'Press a button on the gamepad to connect it.';
      const robot = chosenRobot();
      const axes = state.config.jog.point_axes;
      toolReadout.textContent = robot && robot.point
        ? `${robot.id} tool: ${robot.point.map((v, i) => `${axes[i].name} ${fmt(v, axes[i].unit === 'm' ? 3 : 1)} ${axes[i].unit}`).join(', ')}`
        : 'No arm chosen.';
      if (!reading || !robot) { if (streaming) stop(''); return; }
      const fwd = input.forward || pad.forward;
      const back = input.backward || pad.backward;
      if (!input.deadman) { if (streaming) stop(''); return; }
      sendLive({ type: 'point', robot: robot.id, source, ...reading, deadman: true, forward: fwd, backward: back });
      streaming = true;
      lastWhy = '';
    };
    const timer = setInterval(beat, cfg.beat_ms);
    const lose = () => deadmanOff(prefs.source === 'off' ? '' : 'The page lost focus: the arm stopped and the dead-man is off.');
    window.addEventListener('blur', lose);
    const hidden = () => { if (document.hidden) lose(); };
    document.addEventListener('visibilitychange', hidden);
    const offRefused = onMessage((msg) => { if (msg.type === 'refused' && streaming) deadmanOff(''); });

    root.replaceChildren(
      el('section', { class: 'panel', 'aria-label': 'Handheld pointer' },
        el('h2', {}, 'Move the arm with a phone or a gamepad'),
        el('p', {}, 'With the dead-man on, the tool follows the device: tilt it forward and back to point the tool down and up, tip it left and right to turn the arm. Forward and Back move the tip along the tool.'),
        el('div', { class: 'row setting', role: 'group', 'aria-label': 'Motion control' }, el('span', { class: 'label' }, 'Motion control'), sourceButtons),
        el('div', { class: 'row setting', role: 'group', 'aria-label': 'Dead-man' }, el('span', { class: 'label' }, 'Dead-man'), deadmanModes),
        status,
        el('div', { class: 'row pointer-buttons' }, deadman, backward, forward),
        el('div', { class: 'row' }, gripperButtons()),
        deviceReadout, toolReadout,
        el('p', { class: 'muted' }, 'Gamepad: A is the dead-man, the right shoulder or trigger moves forward, the left ones move back, the left stick tilts, X closes the gripper and B opens it. A phone needs this page over HTTPS (python -m asibot.web --lan) and may ask for permission first.')),
    );
    if (prefs.source === 'phone') window.addEventListener('deviceorientation', onTilt);
    sync();
    return {
      update() {},
      unmount() {
        clearInterval(timer);
        deadmanOff('');
        window.removeEventListener('deviceorientation', onTilt);
        window.removeEventListener('blur', lose);
        document.removeEventListener('visibilitychange', hidden);
        offRefused();
      },
    };
  },
};
