// What choosing a control means when no click chose it: a switch's select (scanning.js) or a
// pointer resting on it (dwell.js). One meaning for both, so every access method reaches the
// same controls and they behave the same.
//
// A hold-to-move control takes the 'scan:select' event: it starts, and hands the chooser its
// stop (`latch(stopIt)`: the next choice stops it; the returned function says it ended by itself).

export const ACTIONABLE = 'button, a[href], input:not([type=hidden]), select, textarea, [contenteditable="true"], [role=button]';
const TEXT_INPUTS = new Set(['text', 'number', 'search', 'email', 'url', 'tel', 'password']);

// Whether `node` takes typed text: a text field, a text area or an editor (contenteditable).
export function takesText(node) {
  if (!node || node === document.body) return false;
  if (node.tagName === 'TEXTAREA' || node.isContentEditable) return true;
  return node.tagName === 'INPUT' && TEXT_INPUTS.has(node.type);
}

// Whether a person can choose `node` now: enabled, shown, on the page.
export function usable(node) {
  if (node.disabled || node.closest('[inert]')) return false;
  if (!node.checkVisibility({ visibilityProperty: true })) return false;
  const r = node.getBoundingClientRect();
  // Off-page elements (the skip link waits at left: -999px) are for keyboards, not for switches.
  return r.width > 0 && r.height > 0 && r.right + window.scrollX > 0 && r.bottom + window.scrollY > 0;
}

// Choose `node`. 'latched': a control that acts while held started and took `latch`;
// 'done': anything else (a list took its next choice, a text field the focus, a button its click).
export function chooseControl(node, latch) {
  const asked = new CustomEvent('scan:select', { cancelable: true, detail: { latch } });
  if (!node.dispatchEvent(asked)) return 'latched';
  if (node.tagName === 'SELECT') {
    // A drop-down list cannot be opened by a script: each choice picks the next option.
    node.selectedIndex = (node.selectedIndex + 1) % node.options.length;
    node.dispatchEvent(new Event('input', { bubbles: true }));
    node.dispatchEvent(new Event('change', { bubbles: true }));
  } else if (takesText(node)) {
    node.focus();    // typing needs a keyboard (the system's on-screen one types here)
  } else {
    node.focus({ preventScroll: true });
    node.click();
    // The ring (or the dwell's mark) is the one marker: a focus outline left behind would be a second one.
    if (document.activeElement === node) node.blur();
  }
  return 'done';
}
