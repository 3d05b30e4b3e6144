// The player of mocap_exaggerate.viz.page: skinned GLB motions side by side, one panel each, seen by
// one camera at one scale; each end effector's path over the whole clip (Kwon & Lee's Figure 3: the
// captured path, its Gaussian average, the exaggerated paths); a timeline; and, when the page carries
// a tuner, the controls that re-run the exaggeration on the local server that served the page.
//
// Bundled with three.js into viewer.js by build.sh. It reads its data from
// <script type="application/json" id="data"> and exposes window.player for tests and the tuner.

import {
  AnimationMixer, Box3, Color, DirectionalLight, GridHelper, Group, HemisphereLight, Mesh, MeshBasicMaterial,
  MeshStandardMaterial, PerspectiveCamera, PlaneGeometry, PropertyBinding, Scene, Vector3, WebGLRenderer,
} from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { Line2 } from 'three/addons/lines/Line2.js';
import { LineGeometry } from 'three/addons/lines/LineGeometry.js';
import { LineMaterial } from 'three/addons/lines/LineMaterial.js';

// The colours of the project's still pictures (viz/posing.py, viz/stills.py): captured grey, exaggerated orange.
const BODY_COLOURS = ['#bfbfc7', '#ff9e40', '#8fb8ee', '#c7a3d9', '#ee9d9a', '#8fd6c5'];
const PATH_COLOURS = ['#6b6b70', '#f08c2e', '#3d7fd9', '#9b59b6', '#d64541', '#16a085'];
const AVERAGE_COLOUR = '#27ae60';
const BACKGROUND = '#f4f4f1';
const SPEEDS = [0.25, 0.5, 1, 2];
const TUNE_DEBOUNCE_MS = 30;  // a burst of input events (one drag step) is one run
const UP = new Vector3(0, 1, 0);

const data = JSON.parse(document.getElementById('data').textContent);
const fps = data.fps;
const $ = (id) => document.getElementById(id);

const player = {
  ready: false, frame: 0, frames: 0, playing: false, figures: data.figures.length, drawnFrames: 0,
  tuned: 0, lastCommand: data.tune ? data.tune.command : null, error: null,
  setFrame, play, pause, load,
};
window.player = player;

const figures = [];          // per panel: {label, notes, group, root, mixer, action, duration, ends, bones, paths, pathGroup}
const lineMaterials = [];    // every path's material, told the panel size before each panel is drawn
const loading = [];          // per figure: the serial of its latest load, so a slower older load never wins
let sigmaFrames = data.sigma_frames;
let time = 0;                // seconds into the clip
let speed = 1;
let showPaths = true;
let cameraMoved = false;     // the viewer has turned the view: resizes and reloads no longer reframe it
let bounds = null;           // the box every figure's joints stay in over the whole clip
let cloud = [];              // x, y, z of every joint on some 200 frames of the clip, for framing them
let homeDirection = null;    // from the framed view's target toward the camera, before any turning
let renderer, scene, camera, controls, reference;

function fail(message) {
  player.error = message;
  const box = $('message');
  box.textContent = message;
  box.hidden = false;
  $('status').textContent = 'failed';
  document.body.dataset.error = '1';
  pause();
}

function hasWebGL() {
  try {
    return Boolean(window.WebGL2RenderingContext && document.createElement('canvas').getContext('webgl2'));
  } catch (error) {
    return false;
  }
}

// ---------------------------------------------------------------------------- loading

function decodeBase64(text) {
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
  return bytes.buffer;
}

function parseGlb(base64) {
  return new Promise((resolve, reject) => {
    new GLTFLoader().parse(decodeBase64(base64), '', resolve, (error) => reject(error instanceof Error ? error : new Error(String(error))));
  });
}

function findNode(root, name) {
  const sanitized = PropertyBinding.sanitizeNodeName(name);
  let found = null;
  root.traverse((node) => {
    if (!found && (node.userData.name === name || node.name === name || node.name === sanitized)) found = node;
  });
  return found;
}

function makeFigure(gltf, index, label, notes) {
  if (!gltf.animations.length) throw new Error(`figure ${index + 1} (${label}) has no animation`);
  const root = gltf.scene;
  const clip = gltf.animations[0];
  const mixer = new AnimationMixer(root);
  const action = mixer.clipAction(clip);
  action.play();
  // A GLB without materials gets three's default, metallic and so near black without an environment.
  const ownMaterials = Boolean(gltf.parser.json.materials && gltf.parser.json.materials.length);
  const bones = [];
  root.traverse((node) => {
    if (node.isMesh) {
      node.frustumCulled = false;  // a skinned body leaves its bind-pose bounds as it runs
      if (!ownMaterials) {
        node.material = new MeshStandardMaterial({ color: BODY_COLOURS[index % BODY_COLOURS.length], roughness: 0.8 });
      }
    }
    if (node.isBone) bones.push(node);
  });
  if (!bones.length) root.traverse((node) => bones.push(node));  // no skin: frame the animated nodes themselves
  const ends = data.ends.map((name) => ({ name, node: findNode(root, name) })).filter((end) => end.node);
  const group = new Group();
  const pathGroup = new Group();
  group.add(root, pathGroup);
  return { label, notes, group, root, mixer, action, duration: clip.duration, ends, bones, paths: new Map(), pathGroup };
}

function disposeFigure(figure) {
  figure.mixer.stopAllAction();
  figure.mixer.uncacheRoot(figure.root);
  figure.group.traverse((node) => {
    if (node.geometry) node.geometry.dispose();
    if (node.material) {
      for (const material of [].concat(node.material)) {
        const at = lineMaterials.indexOf(material);
        if (at >= 0) lineMaterials.splice(at, 1);
        material.dispose();
      }
    }
  });
}

function poseAt(figure, seconds) {
  figure.action.time = Math.min(Math.max(seconds, 0), figure.duration);
  figure.mixer.update(0);  // evaluates the action at its own time, with no looping or wrapping
}

// Every frame's world position of each end; with points, also every joint's on some 200 frames.
function samplePaths(figure, points = null) {
  const where = new Vector3();
  const paths = new Map(figure.ends.map((end) => [end.name, new Float32Array(player.frames * 3)]));
  const every = Math.ceil(player.frames / 200);
  for (let frame = 0; frame < player.frames; frame++) {
    poseAt(figure, frame / fps);
    figure.root.updateMatrixWorld(true);
    for (const end of figure.ends) end.node.getWorldPosition(where).toArray(paths.get(end.name), frame * 3);
    if (points && (frame % every === 0 || frame === player.frames - 1)) {
      for (const bone of figure.bones) points.push(...bone.getWorldPosition(where).toArray());
    }
  }
  figure.paths = paths;
}

// A Gaussian average along time (scipy.ndimage.gaussian_filter1d: truncated at 4 sigma, edges by nearest value).
function gaussianAverage(path, sigma) {
  const count = path.length / 3;
  if (!(sigma > 0)) return Float32Array.from(path);
  const radius = Math.floor(4 * sigma + 0.5);
  const weights = [];
  let total = 0;
  for (let k = -radius; k <= radius; k++) {
    const weight = Math.exp(-0.5 * (k / sigma) ** 2);
    weights.push(weight);
    total += weight;
  }
  const average = new Float32Array(path.length);
  for (let frame = 0; frame < count; frame++) {
    for (let axis = 0; axis < 3; axis++) {
      let sum = 0;
      for (let k = -radius; k <= radius; k++) {
        const at = Math.min(count - 1, Math.max(0, frame + k));
        sum += weights[k + radius] * path[at * 3 + axis];
      }
      average[frame * 3 + axis] = sum / total;
    }
  }
  return average;
}

function pathLine(path, colour, width) {
  const geometry = new LineGeometry();
  geometry.setPositions(path);
  const material = new LineMaterial({ color: new Color(colour), linewidth: width });
  lineMaterials.push(material);
  const line = new Line2(geometry, material);
  line.computeLineDistances();
  line.frustumCulled = false;
  return line;
}

function clearGroup(group) {
  for (const child of [...group.children]) {
    group.remove(child);
    child.geometry.dispose();
    lineMaterials.splice(lineMaterials.indexOf(child.material), 1);
    child.material.dispose();
  }
}

// The captured figure's paths and their average, shown in every panel as the reference.
function drawReference() {
  clearGroup(reference);
  const captured = figures[0];
  if (!captured) return;
  for (const [, path] of captured.paths) {
    if (path.length < 6) continue;
    reference.add(pathLine(path, PATH_COLOURS[0], 2));
    reference.add(pathLine(gaussianAverage(path, sigmaFrames), AVERAGE_COLOUR, 2));
  }
}

function drawOwnPaths(figure, index) {
  clearGroup(figure.pathGroup);
  if (index === 0) return;  // the captured figure's own paths are the reference
  for (const [, path] of figure.paths) {
    if (path.length >= 6) figure.pathGroup.add(pathLine(path, PATH_COLOURS[index % PATH_COLOURS.length], 2.5));
  }
}

function countFrames() {
  const longest = Math.max(...figures.map((figure) => figure.duration));
  player.frames = Math.max(1, Math.round(longest * fps) + 1);  // the frames at 0, 1/fps, ... up to the longest end
  $('timeline').max = String(player.frames - 1);
}

// ---------------------------------------------------------------------------- the view

// Side on to the captured root's travel (so a run goes left to right), turned a little toward its
// front and looking a little down; from the front when the root stays put. It poses the captured
// figure: call it before the figures are put on the current frame.
function viewDirection() {
  const captured = figures[0];
  let across = new Vector3(0, 0, 1);
  let travel = null;
  const root = captured.bones[0];
  if (root) {
    const start = new Vector3();
    const end = new Vector3();
    poseAt(captured, 0);
    captured.root.updateMatrixWorld(true);
    root.getWorldPosition(start);
    poseAt(captured, captured.duration);
    captured.root.updateMatrixWorld(true);
    root.getWorldPosition(end);
    travel = end.sub(start).setY(0);
  }
  if (travel && travel.length() > 0.5) {
    travel.normalize();
    across = new Vector3().crossVectors(travel, UP).normalize();
    across.multiplyScalar(Math.cos(0.35)).addScaledVector(travel, Math.sin(0.35)).normalize();
  } else {
    across.set(Math.sin(0.35), 0, Math.cos(0.35));
  }
  return across.multiplyScalar(Math.cos(0.25)).addScaledVector(UP, Math.sin(0.25)).normalize();
}

function panelSize() {
  const width = Math.max(1, renderer.domElement.clientWidth);
  const height = Math.max(1, renderer.domElement.clientHeight);
  return { width: width / figures.length, height };
}

// Places the camera so that every joint over the clip, with room for the body around it, is in every panel.
function frameCamera() {
  const { width, height } = panelSize();
  camera.aspect = width / height;
  const direction = cameraMoved ? camera.position.clone().sub(controls.target).normalize() : homeDirection;
  const right = new Vector3().crossVectors(UP, direction).normalize();
  const up = new Vector3().crossVectors(direction, right);
  const axes = [right, up, direction];
  const low = [Infinity, Infinity, Infinity];
  const high = [-Infinity, -Infinity, -Infinity];
  const point = new Vector3();
  for (let i = 0; i < cloud.length; i += 3) {
    point.fromArray(cloud, i);
    axes.forEach((axis, a) => {
      const along = point.dot(axis);
      low[a] = Math.min(low[a], along);
      high[a] = Math.max(high[a], along);
    });
  }
  const center = new Vector3();
  axes.forEach((axis, a) => center.addScaledVector(axis, (low[a] + high[a]) / 2));
  const margin = 0.2;  // the body is around its joints: the head's top, the fingers, the soles
  const tanVertical = Math.tan((camera.fov * Math.PI) / 360);
  const tanHorizontal = tanVertical * camera.aspect;
  let distance = 0.1;
  for (let i = 0; i < cloud.length; i += 3) {
    point.fromArray(cloud, i).sub(center);
    const depth = point.dot(direction) + margin;
    distance = Math.max(distance, depth + (Math.abs(point.dot(right)) + margin) / tanHorizontal,
      depth + (Math.abs(point.dot(up)) + margin) / tanVertical);
  }
  distance *= 1.02;
  camera.position.copy(center).addScaledVector(direction, distance);
  camera.near = distance / 100;
  camera.far = distance * 20;
  camera.lookAt(center);
  camera.updateProjectionMatrix();
  controls.target.copy(center);
  controls.update();
}

function makeGround() {
  const extent = bounds.getSize(new Vector3());
  const center = bounds.getCenter(new Vector3());
  const span = Math.max(2, Math.ceil(Math.max(extent.x, extent.z) + 1));
  const floor = Math.min(0, bounds.min.y);  // our GLBs stand on y = 0; one whose joints sink below gets a floor under them
  const ground = new Group();
  const plane = new Mesh(new PlaneGeometry(span, span), new MeshBasicMaterial({ color: new Color('#e6e6e0') }));
  plane.rotation.x = -Math.PI / 2;
  const grid = new GridHelper(span, span * 2, new Color('#b8b8b0'), new Color('#d2d2ca'));
  grid.position.y = 0.001;
  ground.add(plane, grid);
  ground.position.set(Math.round(center.x * 2) / 2, floor, Math.round(center.z * 2) / 2);
  scene.add(ground);
}

let renderQueued = false;
let lastTick = null;

function requestRender() {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(tick);
}

function tick(now) {
  renderQueued = false;
  if (player.playing) {
    if (lastTick !== null) {
      time += ((now - lastTick) / 1000) * speed;
      const end = (player.frames - 1) / fps;
      if (time > end + 0.5 / fps) time = 0;  // loop back to the start after showing the last frame
      showTime();
    }
    lastTick = now;
    requestRender();
  } else {
    lastTick = null;
  }
  render();
}

function render() {
  if (!renderer || !figures.length) return;
  const canvas = renderer.domElement;
  const pixelRatio = window.devicePixelRatio || 1;
  if (canvas.width !== Math.floor(canvas.clientWidth * pixelRatio) || canvas.height !== Math.floor(canvas.clientHeight * pixelRatio)) {
    renderer.setPixelRatio(pixelRatio);
    renderer.setSize(canvas.clientWidth, canvas.clientHeight, false);
    if (bounds && !cameraMoved) frameCamera();
  }
  const { width, height } = panelSize();
  camera.aspect = width / height;
  camera.updateProjectionMatrix();
  renderer.setScissorTest(true);
  reference.visible = showPaths;
  for (const material of lineMaterials) material.resolution.set(width, height);  // CSS pixels: widths too
  figures.forEach((shown, panel) => {
    figures.forEach((figure, index) => { figure.group.visible = index === panel; });
    shown.pathGroup.visible = showPaths;
    const left = Math.round(panel * width);
    const right = Math.round((panel + 1) * width);
    renderer.setViewport(left, 0, right - left, height);
    renderer.setScissor(left, 0, right - left, height);
    renderer.render(scene, camera);
  });
  player.drawnFrames += 1;
}

// ---------------------------------------------------------------------------- time and controls

function frameOf(seconds) {
  return Math.min(player.frames - 1, Math.max(0, Math.floor(seconds * fps + 1e-6)));
}

function showTime() {
  for (const figure of figures) poseAt(figure, time);
  const frame = frameOf(time);
  if (frame !== player.frame || $('timeline').value !== String(frame)) {
    player.frame = frame;
    $('timeline').value = String(frame);
  }
  $('readout').textContent = `frame ${frame} / ${player.frames - 1} · ${(frame / fps).toFixed(2)} s`;
}

function setFrame(frame) {
  if (!figures.length) return;
  const wanted = Math.min(player.frames - 1, Math.max(0, Math.round(Number(frame) || 0)));
  time = wanted / fps;
  lastTick = null;
  showTime();
  requestRender();
}

function play() {
  if (!player.ready || player.playing) return;
  if (player.frame >= player.frames - 1) setFrame(0);
  player.playing = true;
  lastTick = null;
  $('play').textContent = '❚❚';
  $('play').title = 'pause (space)';
  requestRender();
}

function pause() {
  player.playing = false;
  const button = $('play');
  if (button) {
    button.textContent = '▶';
    button.title = 'play (space)';
  }
}

function step(by) {
  pause();
  setFrame(player.frame + by);
}

function wireControls() {
  $('play').addEventListener('click', () => (player.playing ? pause() : play()));
  $('back').addEventListener('click', () => step(-1));
  $('forward').addEventListener('click', () => step(1));
  $('timeline').addEventListener('input', (event) => setFrame(event.target.value));
  const speeds = $('speed');
  for (const value of SPEEDS) speeds.add(new Option(`${value}x`, String(value), value === 1, value === 1));
  speeds.addEventListener('change', () => { speed = Number(speeds.value); });
  $('paths').addEventListener('change', (event) => { showPaths = event.target.checked; requestRender(); });
  document.addEventListener('keydown', (event) => {
    const target = event.target;
    const onTimeline = target === $('timeline');
    if (!onTimeline && target.closest && target.closest('input, select, textarea, [contenteditable]')) return;
    if (event.key === ' ') {
      event.preventDefault();  // no page scroll, and no click of the focused button as well
      if (player.playing) pause(); else play();
    } else if (!onTimeline && (event.key === 'ArrowLeft' || event.key === 'ArrowRight')) {
      event.preventDefault();
      step(event.key === 'ArrowLeft' ? -1 : 1);
    }
  });
  document.addEventListener('keyup', (event) => {
    if (event.key === ' ' && event.target.closest && event.target.closest('button')) event.preventDefault();
  });
}

function setControlsEnabled(enabled) {
  for (const id of ['play', 'back', 'forward', 'timeline', 'speed', 'paths']) $(id).disabled = !enabled;
}

// ---------------------------------------------------------------------------- captions and legend

function swatch(colour) {
  const mark = document.createElement('span');
  mark.className = 'swatch';
  mark.style.background = colour;
  return mark;
}

function drawCaption(index) {
  const figure = figures[index] || data.figures[index];
  const caption = $('captions').children[index];
  caption.replaceChildren();
  const label = document.createElement('div');
  label.className = 'label';
  label.append(swatch(PATH_COLOURS[index % PATH_COLOURS.length]), document.createTextNode(figure.label));
  const notes = document.createElement('table');
  notes.className = 'notes';
  for (const [name, value] of Object.entries(figure.notes || {})) {
    const row = notes.insertRow();
    row.insertCell().textContent = name;
    row.insertCell().textContent = String(value);
  }
  caption.append(label, notes);
}

function drawLegend() {
  const legend = $('legend');
  legend.replaceChildren();
  // Once loaded, the joints some figure has: a name no GLB holds draws nothing.
  const ends = figures.length ? data.ends.filter((name) => figures.some((figure) => figure.ends.some((end) => end.name === name))) : data.ends;
  if (!ends.length) return;
  const item = (colour, text) => {
    const span = document.createElement('span');
    span.append(swatch(colour), document.createTextNode(text));
    legend.append(span);
  };
  const captured = data.figures[0].label;
  item(PATH_COLOURS[0], `${captured} path`);
  item(AVERAGE_COLOUR, `its average (sigma ${Number(sigmaFrames.toFixed(2))} frames)`);
  data.figures.slice(1).forEach((figure, i) => item(PATH_COLOURS[(i + 1) % PATH_COLOURS.length], `${figure.label} path`));
  const joints = document.createElement('span');
  joints.className = 'joints';
  joints.textContent = `(${ends.join(', ')})`;
  legend.append(joints);
}

// ---------------------------------------------------------------------------- replacing a figure

async function load(index, base64) {
  if (!Number.isInteger(index) || index < 0 || index >= figures.length) {
    throw new Error(`no figure ${index}: the page has ${figures.length}`);
  }
  const serial = (loading[index] || 0) + 1;
  loading[index] = serial;
  const gltf = await parseGlb(base64);
  const old = figures[index];
  const figure = makeFigure(gltf, index, old.label, old.notes);
  if (loading[index] !== serial) {  // a later load of this figure came first: it stays
    disposeFigure(figure);
    return;
  }
  const frame = player.frame;
  scene.remove(old.group);
  disposeFigure(old);
  figures[index] = figure;
  scene.add(figure.group);
  countFrames();
  samplePaths(figure);
  if (index === 0) {
    drawReference();
    for (let i = 1; i < figures.length; i++) drawOwnPaths(figures[i], i);  // their paths were sampled over the same frames
  } else {
    drawOwnPaths(figure, index);
  }
  setFrame(frame);
  render();
}

// ---------------------------------------------------------------------------- the tuner

let tuneTimer = null;
let tuneSerial = 0;
let tuneBusy = false;     // a run is on its way
let tunePending = null;  // {presetOnly}: a change made while it was
// The sliders moved since the preset was chosen: only they are sent. A slider snaps a value to its step and
// range, so sending the others changed settings nobody touched (a --stiffness 158 became 160).
const touched = new Set();

function decimals(step) {
  const text = String(step);
  return text.includes('.') ? text.split('.')[1].length : 0;
}

function presetName(preset) {
  return typeof preset === 'string' ? preset : preset.name;
}

function buildTuner(tune) {
  const panel = $('tuner');
  panel.hidden = false;
  const presets = $('preset');
  for (const preset of tune.presets) presets.add(new Option(presetName(preset), presetName(preset)));
  presets.value = tune.preset;
  presets.addEventListener('change', () => {
    const chosen = tune.presets.find((preset) => presetName(preset) === presets.value);
    const own = chosen && typeof chosen === 'object' && chosen.settings;
    if (own) setSliders(own);
    touched.clear();
    scheduleRun(true);
  });
  const list = $('settings');
  for (const setting of tune.settings) {
    const row = document.createElement('label');
    row.className = 'setting';
    const name = document.createElement('span');
    name.className = 'name';
    name.textContent = setting.label || setting.key;
    const shown = document.createElement('output');
    const slider = document.createElement('input');
    slider.type = 'range';
    slider.min = String(setting.min);
    slider.max = String(setting.max);
    slider.step = String(setting.step);
    slider.value = String(setting.value);
    slider.dataset.key = setting.key;
    const unit = setting.unit ? ` ${setting.unit}` : '';
    const say = () => { shown.textContent = `${Number(slider.value).toFixed(decimals(setting.step))}${unit}`; };
    say();
    slider.addEventListener('input', () => { say(); touched.add(slider.dataset.key); scheduleRun(false); });
    slider.say = say;
    row.append(name, shown, slider);
    list.append(row);
  }
  $('command').textContent = tune.command;
  $('toml').textContent = tune.toml;
  $('copy-command').addEventListener('click', () => copyText($('command').textContent, $('copy-command')));
  $('copy-toml').addEventListener('click', () => copyText($('toml').textContent, $('copy-toml')));
}

function sliders() {
  return [...$('settings').querySelectorAll('input[type=range]')];
}

function setSliders(settings) {
  for (const slider of sliders()) {
    if (Object.hasOwn(settings, slider.dataset.key)) {
      slider.value = String(settings[slider.dataset.key]);
      slider.say();
    }
  }
}

function tuneStatus(text, error) {
  const status = $('tune-status');
  status.textContent = text;
  status.classList.toggle('error', Boolean(error));
}

// presetOnly: the preset was changed and the page does not know its settings, so none are sent and the
// server applies the preset alone (its reply's "settings", when given, moves the sliders there).
// A change runs at once (but for a burst of events); a change while a run is on its way runs when it is
// back, with the sliders as they are then: one run at a time, the last values always run, and no wait
// on a timer after a pause (a 150 ms debounce was a third of a 1,000-frame clip's round trip).
function scheduleRun(presetOnly) {
  if (tuneBusy) {
    tunePending = { presetOnly };
    return;
  }
  clearTimeout(tuneTimer);
  tuneTimer = setTimeout(() => startRun(presetOnly), TUNE_DEBOUNCE_MS);
}

async function startRun(presetOnly) {
  tuneBusy = true;
  try {
    await runTuner(presetOnly);
  } finally {
    tuneBusy = false;
    if (tunePending) {
      const next = tunePending;
      tunePending = null;
      startRun(next.presetOnly);
    }
  }
}

async function runTuner(presetOnly) {
  const serial = ++tuneSerial;
  const settings = {};
  for (const slider of sliders()) {
    if (touched.has(slider.dataset.key)) settings[slider.dataset.key] = Number(slider.value);
  }
  tuneStatus('running…', false);
  let reply;
  try {
    const response = await fetch('./run', {
      method: 'POST', headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify({ preset: $('preset').value, settings }),
    });
    const text = await response.text();
    try {
      reply = JSON.parse(text);
    } catch (error) {
      throw new Error(`the server answered ${response.status} ${response.statusText} with no JSON`);
    }
    if (!response.ok && !reply.error) reply = { error: `the server answered ${response.status} ${response.statusText}` };
    if (serial !== tuneSerial) return;  // a newer change is on its way
    if (reply.error) {
      tuneStatus(String(reply.error), true);
      return;
    }
    await load(1, reply.glb);
  } catch (error) {
    if (serial !== tuneSerial) return;
    const served = location.protocol === 'http:' || location.protocol === 'https:';
    tuneStatus(served ? `could not run: ${error.message || error}`
      : 'could not run: the tuner needs its server; open the page at the address the tuning command printed', true);
    return;
  }
  if (serial !== tuneSerial) return;
  figures[1].notes = reply.notes || {};
  drawCaption(1);
  $('command').textContent = reply.command;
  $('toml').textContent = reply.toml;
  player.lastCommand = reply.command;
  if (reply.settings) setSliders(reply.settings);
  if (typeof reply.sigma_frames === 'number' && reply.sigma_frames !== sigmaFrames) {
    sigmaFrames = reply.sigma_frames;
    drawReference();
    drawLegend();
    requestRender();
  }
  player.tuned += 1;
  const seconds = typeof reply.seconds === 'number' ? ` in ${reply.seconds.toFixed(2)} s` : '';
  tuneStatus(`done${seconds}`, false);
}

async function copyText(text, button) {
  let copied = false;
  try {
    if (navigator.clipboard && window.isSecureContext) {
      await navigator.clipboard.writeText(text);
      copied = true;
    }
  } catch (error) {
    copied = false;
  }
  if (!copied) {  // no clipboard API here (or not allowed): select the text and copy it the old way
    const area = document.createElement('textarea');
    area.value = text;
    area.setAttribute('readonly', '');
    area.style.position = 'fixed';
    area.style.opacity = '0';
    document.body.append(area);
    area.select();
    try {
      copied = document.execCommand('copy');
    } catch (error) {
      copied = false;
    }
    area.remove();
  }
  const was = button.dataset.label || button.textContent;
  button.dataset.label = was;
  button.textContent = copied ? 'copied' : 'select and copy by hand';
  setTimeout(() => { button.textContent = was; }, 1500);
}

// ---------------------------------------------------------------------------- start

async function start() {
  $('title').textContent = data.title;
  for (let i = 0; i < data.figures.length; i++) {
    const caption = document.createElement('div');
    caption.className = 'caption';
    $('captions').append(caption);
    drawCaption(i);
  }
  drawLegend();
  wireControls();
  setControlsEnabled(false);
  if (data.tune) buildTuner(data.tune);
  if (!data.figures.length) {
    fail('this page has no figures to show');
    return;
  }
  if (!hasWebGL()) {
    fail('this page needs WebGL (2), which this browser lacks or has turned off: try another browser, or turn on hardware acceleration');
    return;
  }
  try {
    renderer = new WebGLRenderer({ canvas: $('view'), antialias: true });
  } catch (error) {
    fail(`this page needs WebGL, which would not start here: ${error.message || error}`);
    return;
  }
  renderer.setClearColor(new Color(BACKGROUND));
  scene = new Scene();
  scene.add(new HemisphereLight(0xffffff, 0x8a8a80, 2.2));
  const sun = new DirectionalLight(0xffffff, 2.0);
  sun.position.set(3, 6, 4);
  scene.add(sun);
  reference = new Group();
  scene.add(reference);
  camera = new PerspectiveCamera(32, 1, 0.05, 1000);
  controls = new OrbitControls(camera, renderer.domElement);
  controls.addEventListener('start', () => { cameraMoved = true; });
  controls.addEventListener('change', requestRender);
  let loaded;
  try {
    loaded = await Promise.all(data.figures.map((figure) => parseGlb(figure.glb)));
  } catch (error) {
    fail(`a figure's GLB would not load: ${error.message || error}`);
    return;
  }
  try {
    loaded.forEach((gltf, index) => {
      const figure = makeFigure(gltf, index, data.figures[index].label, data.figures[index].notes);
      figures.push(figure);
      loading.push(0);
      scene.add(figure.group);
    });
    countFrames();
    for (const figure of figures) samplePaths(figure, cloud);
    if (!cloud.length) cloud = [-1, 0, -1, 1, 2, 1];
    bounds = new Box3().setFromArray(cloud);
    drawReference();
    figures.forEach((figure, index) => drawOwnPaths(figure, index));
    drawLegend();
    makeGround();
    homeDirection = viewDirection();
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setSize(renderer.domElement.clientWidth, renderer.domElement.clientHeight, false);
    frameCamera();
  } catch (error) {
    fail(`the figures could not be shown: ${error.message || error}`);
    return;
  }
  new ResizeObserver(requestRender).observe($('stage'));  // render() fits the canvas and the camera to the new size
  setControlsEnabled(true);
  setFrame(0);
  render();
  $('status').textContent = '';
  player.ready = true;
  document.body.dataset.ready = '1';
  play();
}

start().catch((error) => fail(`the player stopped: ${error.message || error}`));
