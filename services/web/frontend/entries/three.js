// three.js, its orbit controls and the URDF loader, as one module for the 3D view.
export * from 'three';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
export { default as URDFLoader } from 'urdf-loader';
