// The page's microphone to the voice service: float32 mono frames of about 100 ms at the
// AudioContext's own rate, as binary WebSocket messages (the server resamples nothing: the
// voice service does). One microphone for the whole page, whichever tab is open.
import { onMessage, sendLive, sendSound } from './api.js';

const FRAME_S = 0.1;
let live = null;   // { context, stream, node }
const listeners = new Set();

export function onListening(fn) { listeners.add(fn); return () => listeners.delete(fn); }
function tell(on, why = '') { for (const fn of listeners) fn(on, why); }
export function listening() { return live !== null; }

export async function startListening() {
  if (live) return;
  if (!navigator.mediaDevices || !navigator.mediaDevices.getUserMedia) {
    throw new Error('This browser gives no microphone to the page (it needs https:// or this machine).');
  }
  // The sound as the microphone gives it: the browser's processing for calls (echo cancelling,
  // noise suppression, automatic gain) adapts as it goes, so one word said the same way twice
  // reached the recogniser as two different sounds, and a word learned from one saying did not
  // match the next (one recording played in a loop was read as 'S L AO R OW N D L ER', 'G AO R OW N'
  // and 'L ER OW G'; unprocessed, the same phones each time). The voice service finds the speech
  // against the room's own noise itself, and the recogniser evens out the level.
  const stream = await navigator.mediaDevices.getUserMedia({
    audio: { channelCount: 1, echoCancellation: false, noiseSuppression: false, autoGainControl: false },
  });
  const context = new AudioContext();
  await context.audioWorklet.addModule('/static/js/mic-worklet.js');
  const node = new AudioWorkletNode(context, 'asibot-capture');
  const frame = new Float32Array(Math.round(context.sampleRate * FRAME_S));
  let filled = 0;
  node.port.onmessage = (e) => {
    let samples = e.data;
    while (samples.length) {
      const n = Math.min(samples.length, frame.length - filled);
      frame.set(samples.subarray(0, n), filled);
      filled += n;
      samples = samples.subarray(n);
      if (filled === frame.length) { sendSound(frame.slice().buffer); filled = 0; }
    }
  };
  context.createMediaStreamSource(stream).connect(node);
  await context.resume();
  live = { context, stream, node };
  sendLive({ type: 'mic', rate: context.sampleRate });
  tell(true);
}

export function stopListening(why = '') {
  if (!live) return;
  sendLive({ type: 'mic', rate: null });
  live.stream.getTracks().forEach((t) => t.stop());
  live.context.close();
  live = null;
  tell(false, why);
}

// The server stops a page's listening when a frame is bad (it says why); a lost connection
// stops it too, and the page starts again on the person's say, not by itself.
onMessage((msg) => {
  if (msg.type === 'mic-stopped') stopListening(msg.text);
  // a new connection is a new page id: tell the server again that this page listens
  if (msg.type === 'hello' && live) sendLive({ type: 'mic', rate: live.context.sampleRate });
});
