// Small helpers to build the DOM and tell the user what happened.

// el('button', {class: 'primary', onclick: f}, 'Run') -> <button class="primary">Run</button>
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [key, value] of Object.entries(attrs)) {
    if (value === undefined || value === null || value === false) continue;
    if (key.startsWith('on')) node.addEventListener(key.slice(2), value);
    else if (key === 'class') node.className = value;
    else if (key === 'dataset') Object.assign(node.dataset, value);
    else if (value === true) node.setAttribute(key, '');
    else node.setAttribute(key, value);
  }
  for (const child of children.flat()) {
    if (child === null || child === undefined || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

let noticeTimer = null;

// Show a sentence under the tabs: errors stay until dismissed, good news fades.
export function notify(text, kind = 'error') {
  const box = document.getElementById('notice');
  box.replaceChildren(el('span', {}, text),
    el('button', { type: 'button', onclick: () => { box.hidden = true; } }, 'Dismiss'));
  box.className = kind === 'error' ? 'notice' : 'notice info';
  box.setAttribute('role', kind === 'error' ? 'alert' : 'status');
  box.hidden = false;
  clearTimeout(noticeTimer);
  if (kind !== 'error') noticeTimer = setTimeout(() => { box.hidden = true; }, 4000);
}

// Run an action; a refusal becomes a notice with the server's sentence, never a console error.
export async function attempt(action, success) {
  try {
    const result = await action();
    if (success) notify(typeof success === 'function' ? success(result) : success, 'info');
    return result;
  } catch (e) {
    notify(e.message);
    return undefined;
  }
}

export function fmt(value, digits = 3) {
  return value === null || value === undefined ? '–' : Number(value).toFixed(digits);
}
