// The physpose report's interactive part: a three.js viewer of the motion over the ground
// (play, pause, scrub, orbit, kinematic/physics toggle, foot contacts) and the time plots.
// Reads its data from <script type="application/json" id="physpose-data">.
import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { drawPlot } from "./plots.js";

const COLORS = { physics: 0x2f6fd6, kinematic: 0xf08a24 };
const CONTACT_COLOR = 0xe0245e;

const data = JSON.parse(document.getElementById("physpose-data").textContent);
const T = data.frames;
const state = { frame: 0, playing: false, last: null, show: data.default_motion };

// ---- 3d scene (z up, metres) ----
const canvas = document.getElementById("view");
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xeef1f5);
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 200);
camera.up.set(0, 0, 1);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(3, -4, 6);
scene.add(sun);

const center = new THREE.Vector3(...data.center);
const extent = Math.max(2, data.extent);
const groundSize = 2 * Math.ceil(extent + 10);  // m, reaches past the view's horizon
// The ground: a plane with a 1 m / 0.5 m grid texture (textured triangles rather than long
// lines, which some software renderers drop when they cross the camera plane).
function gridTexture() {
  const c = document.createElement("canvas");
  c.width = c.height = 256;
  const g = c.getContext("2d");
  g.fillStyle = "#e6e9ed";
  g.fillRect(0, 0, 256, 256);
  g.fillStyle = "#b4bcc6";
  g.fillRect(126, 0, 4, 256);
  g.fillRect(0, 126, 256, 4);
  g.fillStyle = "#7d8794";
  g.fillRect(0, 0, 256, 5);
  g.fillRect(0, 0, 5, 256);
  const tex = new THREE.CanvasTexture(c);
  tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
  tex.repeat.set(groundSize, groundSize);
  tex.anisotropy = renderer.capabilities.getMaxAnisotropy();
  tex.colorSpace = THREE.SRGBColorSpace;
  return tex;
}
const floor = new THREE.Mesh(
  new THREE.PlaneGeometry(groundSize, groundSize),
  new THREE.MeshLambertMaterial({ map: gridTexture(), side: THREE.DoubleSide }),
);
// Whole metres stay on grid lines: the texture repeats every metre from the plane's corner.
floor.position.set(Math.round(center.x), Math.round(center.y), 0);
scene.add(floor);

camera.position.set(center.x + 2.2, center.y - 3.6, 1.9);
const controls = new OrbitControls(camera, canvas);
controls.target.set(center.x, center.y, 0.9);
controls.update();

function geometryOf(g) {
  const [a, b, c] = g.size;
  let geo;
  if (g.kind === "capsule") geo = new THREE.CapsuleGeometry(a, 2 * b, 6, 14).rotateX(Math.PI / 2);
  else if (g.kind === "cylinder") geo = new THREE.CylinderGeometry(a, a, 2 * b, 16).rotateX(Math.PI / 2);
  else if (g.kind === "box") geo = new THREE.BoxGeometry(2 * a, 2 * b, 2 * c);
  else if (g.kind === "ellipsoid") geo = new THREE.SphereGeometry(1, 16, 12).scale(a, b, c);
  else geo = new THREE.SphereGeometry(a, 16, 12);
  return geo;
}

function place(obj, pos, quatWxyz) {
  obj.position.set(pos[0], pos[1], pos[2]);
  obj.quaternion.set(quatWxyz[1], quatWxyz[2], quatWxyz[3], quatWxyz[0]);
}

for (const g of (data.body && data.body.scene) || []) {
  const mesh = new THREE.Mesh(geometryOf(g), new THREE.MeshLambertMaterial({ color: 0x9a8f7d }));
  place(mesh, g.pos, g.quat);
  scene.add(mesh);
}

// One figure per motion: capsule body when its body poses are stored, else a stick skeleton.
const figures = {};
for (const [name, m] of Object.entries(data.motions)) {
  const group = new THREE.Group();
  const color = COLORS[name];
  const fig = { group, motion: m, bodies: [], joints: [], bones: null, contacts: [] };
  if (m.body_pos && data.body) {
    const mat = new THREE.MeshStandardMaterial({ color, roughness: 0.7, metalness: 0.0 });
    for (let b = 0; b < data.body.names.length; b++) {
      const bg = new THREE.Group();
      group.add(bg);
      fig.bodies.push(bg);
    }
    for (const g of data.body.geoms) {
      const mesh = new THREE.Mesh(geometryOf(g), mat);
      place(mesh, g.pos, g.quat);
      fig.bodies[g.body].add(mesh);
    }
  } else {
    const mat = new THREE.MeshStandardMaterial({ color });
    const sphere = new THREE.SphereGeometry(0.03, 10, 8);
    for (let j = 0; j < data.joint_names.length; j++) {
      const s = new THREE.Mesh(sphere, mat);
      group.add(s);
      fig.joints.push(s);
    }
    const pts = new Float32Array(data.edges.length * 6);
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(pts, 3));
    fig.bones = new THREE.LineSegments(geo, new THREE.LineBasicMaterial({ color }));
    group.add(fig.bones);
  }
  const disc = new THREE.CircleGeometry(0.09, 24);
  for (let k = 0; k < 2; k++) {
    const marker = new THREE.Mesh(disc, new THREE.MeshBasicMaterial({
      color: CONTACT_COLOR, transparent: true, opacity: 0.85 }));
    marker.position.z = 0.004;
    group.add(marker);
    fig.contacts.push(marker);
  }
  scene.add(group);
  figures[name] = fig;
}

function v3(arr, t, i, n) {
  const o = (t * n + i) * 3;
  return [arr[o], arr[o + 1], arr[o + 2]];
}

function poseFigure(fig, t) {
  const m = fig.motion;
  const nb = fig.bodies.length;
  for (let b = 0; b < nb; b++) {
    const o = (t * nb + b) * 4;
    place(fig.bodies[b], v3(m.body_pos, t, b, nb), m.body_quat.slice(o, o + 4));
  }
  const nj = data.joint_names.length;
  fig.joints.forEach((s, j) => s.position.set(...v3(m.joints, t, j, nj)));
  if (fig.bones) {
    const pos = fig.bones.geometry.attributes.position;
    data.edges.forEach(([a, b], e) => {
      pos.setXYZ(2 * e, ...v3(m.joints, t, a, nj));
      pos.setXYZ(2 * e + 1, ...v3(m.joints, t, b, nj));
    });
    pos.needsUpdate = true;
  }
  fig.contacts.forEach((marker, k) => {
    const p = m.feet_xy[(t * 2 + k)];
    marker.position.x = p[0];
    marker.position.y = p[1];
    marker.visible = !!m.contacts[t * 2 + k];
  });
}

// ---- controls ----
const frameLabel = document.getElementById("frame");
const timeLabel = document.getElementById("time");
const slider = document.getElementById("scrub");
const playButton = document.getElementById("play");
slider.max = String(T - 1);

const plotCanvases = [];
const plotsRoot = document.getElementById("plots");
for (const spec of data.plots) {
  const box = document.createElement("div");
  box.className = "plot";
  const c = document.createElement("canvas");
  c.id = "plot-" + spec.id;
  box.appendChild(c);
  plotsRoot.appendChild(box);
  plotCanvases.push([c, spec]);
}

// Follow the body: move the orbit target (and the camera with it) to the shown pelvis.
const followBox = document.getElementById("follow");
function follow() {
  if (!followBox.checked) return;
  const m = data.motions[state.show in data.motions ? state.show : data.default_motion];
  const nj = data.joint_names.length;
  const [x, y] = v3(m.joints, state.frame, 0, nj);
  const dx = x - controls.target.x, dy = y - controls.target.y;
  controls.target.x += dx; controls.target.y += dy;
  camera.position.x += dx; camera.position.y += dy;
}

function showFrame(t) {
  state.frame = ((t % T) + T) % T;
  follow();
  for (const [name, fig] of Object.entries(figures)) {
    fig.group.visible = state.show === "both" || state.show === name;
    poseFigure(fig, state.frame);
  }
  frameLabel.textContent = String(state.frame + 1);
  timeLabel.textContent = (state.frame / data.fps).toFixed(2);
  slider.value = String(state.frame);
  for (const [c, spec] of plotCanvases) drawPlot(c, spec, state.frame / data.fps);
}

function setPlaying(on) {
  state.playing = on;
  state.last = null;
  playButton.textContent = on ? "Pause" : "Play";
  playButton.setAttribute("aria-pressed", on ? "true" : "false");
}

playButton.addEventListener("click", () => setPlaying(!state.playing));
slider.addEventListener("input", () => { setPlaying(false); showFrame(Number(slider.value)); });
for (const radio of document.querySelectorAll("input[name=motion]")) {
  if (!(radio.value in figures) && radio.value !== "both") radio.disabled = true;
  radio.checked = radio.value === state.show;
  radio.addEventListener("change", () => { state.show = radio.value; showFrame(state.frame); });
}
window.addEventListener("keydown", (e) => {
  if (e.target.tagName === "INPUT" && e.target.type !== "range") return;
  if (e.code === "Space") { e.preventDefault(); setPlaying(!state.playing); }
  if (e.code === "ArrowRight") { setPlaying(false); showFrame(state.frame + 1); }
  if (e.code === "ArrowLeft") { setPlaying(false); showFrame(state.frame - 1); }
});

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  for (const [c, spec] of plotCanvases) drawPlot(c, spec, state.frame / data.fps);
}
window.addEventListener("resize", resize);

function tick(now) {
  if (state.playing) {
    if (state.last === null) state.last = now;
    const steps = Math.floor(((now - state.last) / 1000) * data.fps);
    if (steps > 0) {
      state.last += (steps * 1000) / data.fps;
      showFrame(state.frame + steps);
    }
  }
  controls.update();
  renderer.render(scene, camera);
  requestAnimationFrame(tick);
}

resize();
showFrame(0);
requestAnimationFrame(tick);
window.physposeViewer = { showFrame, setPlaying, state };
