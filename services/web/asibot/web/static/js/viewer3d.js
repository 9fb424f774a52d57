// The 3D view of the commanded robot: its URDF drawn with three.js and urdf-loader (bundled from
// npm, served by our server), following the live joint state, plus a see-through "ghost" of a
// target before it is sent. Under it: Pause (the picture stops following the arm, WCAG 2.2.2) and
// buttons that turn and zoom the view, so dragging is never the only way (WCAG 2.5.7, 2.1.1).
// "Show camera points" draws what the robot's depth cameras see, as coloured points in the
// robot's frame (the server's cloud: services/web/asibot/web/world.py), refreshed a few times a
// second while the view is on screen (each ask names the cloud drawn, and a still world's is not
// sent or drawn again); the picture's data-points says how many are drawn.
import * as THREE from '/static/vendor/three.js';
import { api, chosenRobot, onChange, paths } from './api.js';
import { el, notify } from './ui.js';

const SOLID = new THREE.MeshStandardMaterial({ color: 0x4f7fb0, metalness: 0.2, roughness: 0.55 });
// How often the camera points are fetched while shown, ms; the camera list is asked again this often.
const CLOUD_MS = 333;
const CAMERAS_MS = 5000;
const POINTS = new THREE.PointsMaterial({ size: 0.03, vertexColors: true });
const CLOUD_SHOWN = 'asibot.cloud';
// Frames at least this far apart (25 a second), ms; a joint that moved less than SEEN_DEG is not redrawn.
const FRAME_MS = 40;
const SEEN_DEG = 0.05;
// Drawn in software (no graphics card: SwiftShader, llvmpipe), a frame costs the CPU that the
// robot's own services need: 10 a second, without antialiasing, at one pixel a pixel.
const SOFTWARE_FRAME_MS = 100;
const SOFTWARE_RENDERER = /swiftshader|llvmpipe|softpipe|software|basic render/i;
const GHOST = new THREE.MeshStandardMaterial({ color: 0xff9f1a, transparent: true, opacity: 0.35, depthWrite: false });

// Whether this browser draws WebGL without a graphics card, asked once of a throwaway context
// (the answer decides how each view's context is made: antialiasing cannot be turned off later).
let software = null;
function drawnInSoftware() {
  if (software !== null) return software;
  const canvas = document.createElement('canvas');
  const gl = canvas.getContext('webgl2') || canvas.getContext('webgl');
  if (!gl) return (software = false);
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  const lose = gl.getExtension('WEBGL_lose_context');
  if (lose) lose.loseContext();
  return (software = SOFTWARE_RENDERER.test(name));
}

function paint(robot, material) {
  robot.traverse((o) => { if (o.isMesh) { o.material = material; o.castShadow = false; } });
}

export class RobotViewer {
  constructor() {
    this.picture = el('div', { class: 'viewer', role: 'img', 'aria-label': '3D view of the robot' });
    this.legend = el('p', { class: 'legend', role: 'status' });
    this.pauseButton = el('button', { type: 'button', 'aria-pressed': 'false', onclick: () => this.pause(!this.paused) }, 'Pause');
    this.cloudButton = el('button', { type: 'button', 'aria-pressed': 'false', onclick: () => this.showCloud(!this.cloudShown) }, 'Show camera points');
    this.root = el('div', { class: 'viewer-box' }, this.picture,
      el('div', { class: 'row viewer-bar', role: 'group', 'aria-label': '3D view controls' },
        el('button', { type: 'button', onclick: () => this.turn(-1) }, 'Turn left'),
        el('button', { type: 'button', onclick: () => this.turn(1) }, 'Turn right'),
        el('button', { type: 'button', onclick: () => this.zoom(0.8) }, 'Closer'),
        el('button', { type: 'button', onclick: () => this.zoom(1.25) }, 'Farther'),
        this.pauseButton, this.cloudButton),
      this.legend);
    this.paused = false;
    this.latest = null;   // the joints that came while paused
    this.pause(false);
    const inSoftware = drawnInSoftware();
    this.picture.dataset.renderer = inSoftware ? 'software' : 'gpu';
    this.renderer = new THREE.WebGLRenderer({ antialias: !inSoftware, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(inSoftware ? 1 : Math.min(window.devicePixelRatio, 2));
    const frameMs = inSoftware ? SOFTWARE_FRAME_MS : FRAME_MS;
    this.picture.prepend(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xe9eef2);
    this.camera = new THREE.PerspectiveCamera(45, 4 / 3, 0.01, 50);
    this.camera.position.set(1.6, 1.3, 1.6);
    this.controls = new THREE.OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 0.5, 0);
    this.controls.update();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(2, 4, 3);
    this.scene.add(sun);
    const grid = new THREE.GridHelper(2, 20, 0x8899aa, 0xc5ced6);
    this.scene.add(grid);
    // The camera points, in the robot's frame: z-up like the URDF, turned as the robot is.
    this.cloudFrame = new THREE.Group();
    this.cloudFrame.rotation.x = -Math.PI / 2;
    this.scene.add(this.cloudFrame);
    this.clouds = new Map();     // camera name -> THREE.Points
    this.depthCameras = { robot: null, names: [], at: 0 };
    this.fetching = false;
    this.showCloud(localStorage.getItem(CLOUD_SHOWN) !== 'off');
    setInterval(() => this.refreshCloud(), CLOUD_MS);
    this.robotId = null;
    this.robot = null;
    this.ghost = null;
    this.dirty = true;
    this.controls.addEventListener('change', () => { this.dirty = true; });
    new ResizeObserver(() => this.resize()).observe(this.picture);
    // Draw only what changed, and at most FRAME_MS apart: without a GPU every frame costs a core.
    let drawn = 0;
    const loop = (now) => {
      if (this.dirty && this.picture.isConnected && now - drawn >= frameMs) {
        this.renderer.render(this.scene, this.camera);
        this.dirty = false;
        drawn = now;
      }
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  resize() {
    const w = this.picture.clientWidth, h = this.picture.clientHeight;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  async show(robotId) {
    if (robotId === this.robotId) return;
    this.robotId = robotId;
    for (const r of [this.robot, this.ghost]) if (r) this.scene.remove(r);
    this.dropClouds();
    this.robot = this.ghost = null;
    if (!robotId) { this.dirty = true; return; }
    const model = await api.get(paths.robot.model(robotId));
    const loader = new THREE.URDFLoader();
    const make = (material) => {
      const robot = loader.parse(model.urdf);
      robot.rotation.x = -Math.PI / 2;   // URDF is z-up, three.js is y-up
      paint(robot, material);
      this.scene.add(robot);
      return robot;
    };
    this.robot = make(SOLID);
    this.ghost = make(GHOST);
    this.ghost.visible = false;
    // The joints that came while the model loaded: a still arm sends no new ones.
    if (this.latest && robotId === this.robotId) this.setJoints(...this.latest);
    this.dirty = true;
  }

  showCloud(on) {
    this.cloudShown = on;
    localStorage.setItem(CLOUD_SHOWN, on ? 'on' : 'off');
    this.cloudButton.setAttribute('aria-pressed', String(on));
    this.cloudFrame.visible = on;
    this.dirty = true;
    if (on) this.refreshCloud();
  }

  dropClouds() {
    for (const points of this.clouds.values()) { this.cloudFrame.remove(points); points.geometry.dispose(); }
    this.clouds.clear();
    this.picture.dataset.points = '0';
    this.dirty = true;
  }

  // Fetch every depth camera's points (one at a time: a slow answer is never overtaken).
  async refreshCloud() {
    if (!this.cloudShown || this.paused || this.fetching || !this.robotId || !this.picture.isConnected || document.hidden) return;
    this.fetching = true;
    const robot = this.robotId;
    try {
      const now = Date.now();
      if (this.depthCameras.robot !== robot || now - this.depthCameras.at > CAMERAS_MS) {
        const { cameras } = await api.get(paths.robot.depthCameras(robot));
        this.depthCameras = { robot, names: cameras.filter((c) => c.pose_from).map((c) => c.name), at: now };
      }
      for (const name of [...this.clouds.keys()]) {
        if (!this.depthCameras.names.includes(name)) { this.cloudFrame.remove(this.clouds.get(name)); this.clouds.delete(name); }
      }
      for (const name of this.depthCameras.names) {
        const points = this.clouds.get(name);
        const { data, tag } = await api.bytes(paths.robot.cloud(robot, name), points ? points.userData.tag : null);
        // Paused while the answer came: the picture keeps what it showed (CI: "the paused picture moved").
        if (robot !== this.robotId || this.paused) return;
        if (data) this.drawCloud(name, data, tag);
      }
    } catch (e) {
      this.depthCameras.at = 0;   // a camera stopped, or was never calibrated: ask again next time
    } finally {
      this.fetching = false;
    }
  }

  // The server's cloud: uint32 N, N x 3 float32 x y z, N x 3 uint8 r g b (world.CLOUD_HEADER).
  drawCloud(name, buffer, tag) {
    const n = new DataView(buffer).getUint32(0, true);
    const xyz = new Float32Array(buffer, 4, n * 3);
    const rgb = new Uint8Array(buffer, 4 + n * 12, n * 3);
    let points = this.clouds.get(name);
    if (points) points.geometry.dispose();
    else { points = new THREE.Points(new THREE.BufferGeometry(), POINTS); this.cloudFrame.add(points); this.clouds.set(name, points); }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(xyz.slice(), 3));
    geometry.setAttribute('color', new THREE.BufferAttribute(rgb.slice(), 3, true));
    points.geometry = geometry;
    points.userData.tag = tag;
    let total = 0;
    for (const p of this.clouds.values()) total += p.geometry.getAttribute('position').count;
    this.picture.dataset.points = String(total);
    this.dirty = true;
  }

  // Paused, the picture keeps the arm where it was; resuming shows where it is now.
  pause(on) {
    this.paused = on;
    this.pauseButton.setAttribute('aria-pressed', String(on));
    this.legend.textContent = on ? 'Paused: the picture shows the arm as it was. Touch Pause again to follow it.'
      : 'Blue: the arm now. Orange: the target before you send it. Dots: what the cameras see.';
    if (!on && this.latest) this.setJoints(...this.latest);
  }

  // Turn the camera around the robot by 20 degrees (direction -1 or 1), or move it closer/farther.
  turn(direction) {
    const offset = this.camera.position.clone().sub(this.controls.target);
    offset.applyAxisAngle(new THREE.Vector3(0, 1, 0), direction * THREE.MathUtils.degToRad(20));
    this.camera.position.copy(this.controls.target).add(offset);
    this.controls.update();
    this.dirty = true;
  }

  zoom(factor) {
    const offset = this.camera.position.clone().sub(this.controls.target);
    const length = THREE.MathUtils.clamp(offset.length() * factor, 0.4, 8);
    this.camera.position.copy(this.controls.target).add(offset.setLength(length));
    this.controls.update();
    this.dirty = true;
  }

  // names and degrees, as the server's robot view gives them
  setJoints(names, degrees) {
    this.latest = [names, degrees];
    if (!this.robot || this.paused) return;
    // Every robot's news calls this; a still arm (or one that moved less than anyone can see) draws nothing.
    const drawn = this.drawnJoints;
    if (drawn && drawn.robot === this.robot && drawn.names.join() === names.join()
        && degrees.every((d, i) => Math.abs(d - drawn.degrees[i]) < SEEN_DEG)) return;
    this.drawnJoints = { robot: this.robot, names, degrees: [...degrees] };
    names.forEach((name, i) => this.robot.setJointValue(name, THREE.MathUtils.degToRad(degrees[i])));
    this.dirty = true;
  }

  showGhost(names, degrees) {
    if (!this.ghost) return;
    if (!names) { this.ghost.visible = false; this.picture.dataset.ghost = 'hidden'; this.dirty = true; return; }
    names.forEach((name, i) => this.ghost.setJointValue(name, THREE.MathUtils.degToRad(degrees[i])));
    this.ghost.visible = true;
    this.picture.dataset.ghost = degrees.map((d) => d.toFixed(1)).join(' ');   // what the ghost shows, for tests
    this.dirty = true;
  }
}

// One viewer for the whole page: views hand its element around instead of making new WebGL contexts.
// Made when a page first shows it (a page that never does makes no WebGL context and loads no
// model); from then on it follows the commanded robot and its joints.
let shared = null;
export function viewer() {
  if (!shared) {
    const made = new RobotViewer();
    const follow = () => {
      const robot = chosenRobot();
      if (!robot) return;
      // Checked here, not only in show(): the feed changes up to 30 times a second.
      if (robot.id !== made.robotId) made.show(robot.id).catch((e) => notify(e.message));
      if (robot.joints) made.setJoints(robot.joints.names, robot.joints.deg);
    };
    shared = made;
    onChange(follow);
    follow();
  }
  return shared;
}
