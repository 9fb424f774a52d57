// What the person typed stays where they typed it. A view is built again each time its tab is
// shown, so its form fields take their last values from here: kept for this browser tab
// (sessionStorage), across tab switches and reloads. Unsaved program text is kept apart, as
// drafts (views/program.js).
const PREFIX = 'asibot.kept.';

export function recall(key, fallback = null) {
  try {
    const text = sessionStorage.getItem(PREFIX + key);
    return text === null ? fallback : JSON.parse(text);
  } catch (e) {
    return fallback;   // a value from an older page
  }
}

export function remember(key, value) {
  if (value === null || value === undefined) sessionStorage.removeItem(PREFIX + key);
  else sessionStorage.setItem(PREFIX + key, JSON.stringify(value));
}

// A select takes a kept value only if it is one of its options (they may come later: call
// kept.restore(field) once they are there).
function restore(field) {
  const value = recall(field.dataset.kept);
  if (typeof value !== 'string') return;
  if (field.tagName === 'SELECT' && ![...field.options].some((o) => o.value === value)) return;
  field.value = value;
}

// `field` (an input or a select) keeps its value under `key`: it starts with the kept one and
// every change is kept. Returns the field.
export function kept(key, field) {
  field.dataset.kept = key;
  restore(field);
  const save = () => remember(key, field.value);
  field.addEventListener('input', save);
  field.addEventListener('change', save);
  return field;
}
kept.restore = restore;

// Set a kept field from the page's code (a copy of the arm's point, a cleared name).
export function setKept(field, value) {
  field.value = value;
  if (field.dataset.kept) remember(field.dataset.kept, field.value);
}
