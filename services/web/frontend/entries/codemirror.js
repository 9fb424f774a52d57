// CodeMirror 6 with Python, as one module for the Program tab's editor.
export { basicSetup } from 'codemirror';
export { EditorView, keymap, lineNumbers } from '@codemirror/view';
export { EditorState, StateEffect, StateField } from '@codemirror/state';
export { python } from '@codemirror/lang-python';
