// The mocodec viewer: the original and the decoded motion in sync, the decoded joints coloured
// by their error, the error over time, the numbers, and re-encoding with another codec or knob;
// or, with ?room=R&token=T, every avatar of a relay room live with the bit rate it gets.
// Joint positions come from the server in metres (forward kinematics is done there).
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { Figure, f32 } from "/static/figure.js";

const $ = (id) => document.getElementById(id);
const state = { ready: false, playing: false, frame: 0, frames: 0, fps: 30, time: 0, numbers: null, codecs: [] };
window.viewerState = state;            // read by the browser tests

// ----- the 3-D view ----------------------------------------------------------------------------
const view = $("view");
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
view.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xfafafa);
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 200);
const controls = new OrbitControls(camera, renderer.domElement);
scene.add(new THREE.GridHelper(40, 40, 0x999999, 0xdddddd));

function resize() {
  const w = view.clientWidth, h = view.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener("resize", resize);

// ----- the clip ----------------------------------------------------------------------------------
let clip = null, original = null, decoded = null, lastRoot = null;
const SPACING = 1.2;                   // metres between the two figures side by side

function heat(value, max) {
  const t = max > 0 ? Math.min(value / max, 1) : 0;
  return new THREE.Color().setHSL(0.62 * (1 - t), 0.85, 0.5);
}

function show(data) {
  clip = {
    fps: data.fps, frames: data.frames, joints: data.joints.length, parents: data.parents,
    original: f32(data.original),
    decoded: data.decoded ? f32(data.decoded) : null,
    error: data.error_cm ? f32(data.error_cm) : null,
  };
  state.frames = clip.frames; state.fps = clip.fps; state.numbers = data.numbers;
  $("clip-name").textContent = data.name;
  $("scrub").max = String(Math.max(clip.frames - 1, 0));
  if (!original) {
    original = new Figure(scene, clip.parents, 0x3b4a6b, 0x3b4a6b);
    decoded = new Figure(scene, clip.parents, 0x555555, 0x2a6fdb);
  }
  decoded.group.visible = Boolean(clip.decoded);
  numbers(data.numbers);
  chart();
  layout();
  draw();
}

function numbers(n) {
  const fmt = (v, d, unit) => (v === null || v === undefined ? "–" : `${Number(v).toFixed(d)}${unit}`);
  $("n-codec").textContent = n ? n.codec : "–";
  $("n-ratio").textContent = n ? `${n.ratio.toFixed(2)} : 1` : "–";
  $("n-bitrate").textContent = n ? `${(n.bits_per_second / 1000).toFixed(2)} kbit/s` : "–";
  $("n-mean").textContent = n ? fmt(n.mean_joint_error_cm, 3, " cm") : "–";
  $("n-max").textContent = n ? fmt(n.max_joint_error_cm, 3, " cm") : "–";
  $("n-psnr").textContent = n ? fmt(n.psnr_db, 2, " dB") : "–";
  $("n-vpsnr").textContent = n ? fmt(n.vpsnr_db, 2, " dB") : "–";
  $("legend-max").textContent = n ? `${Number(n.max_joint_error_cm).toFixed(2)}` : "max";
}

function layout() {
  const side = $("layout").value === "side";
  decoded.group.position.set(side ? SPACING : 0, 0, 0);
  decoded.lines.material.color.set(side ? 0x555555 : 0xd7301f);
  lastRoot = null;
}

function draw() {
  if (!clip) return;
  const f = Math.min(state.frame, clip.frames - 1);
  original.pose(clip.original, f);
  if (clip.decoded) {
    decoded.pose(clip.decoded, f);
    const max = state.numbers ? state.numbers.max_joint_error_cm : 1;
    const row = clip.error.subarray(f * clip.joints, (f + 1) * clip.joints);
    decoded.colour(Array.from(row, (e) => heat(e, max)));
  }
  // the camera follows the figures: move it with the root
  const root = new THREE.Vector3(clip.original[f * clip.joints * 3], 0.9, clip.original[f * clip.joints * 3 + 2]);
  root.x += decoded.group.position.x / 2;
  if (lastRoot === null) {
    controls.target.copy(root);
    camera.position.set(root.x + 0.8, 1.5, root.z + 3.4);
  } else {
    const delta = root.clone().sub(lastRoot);
    controls.target.add(delta);
    camera.position.add(delta);
  }
  lastRoot = root;
  controls.update();
  $("scrub").value = String(f);
  $("frame-label").textContent = `${f} / ${clip.frames - 1}`;
  cursor(f);
  renderer.render(scene, camera);
}

// ----- the error chart ---------------------------------------------------------------------------
let chartImage = null;
function chart() {
  const canvas = $("chart"), g = canvas.getContext("2d");
  canvas.width = canvas.clientWidth || 900;
  g.clearRect(0, 0, canvas.width, canvas.height);
  if (!clip || !clip.error) { chartImage = null; return; }
  const J = clip.joints, F = clip.frames, mean = new Float32Array(F), max = new Float32Array(F);
  for (let f = 0; f < F; f++) {
    let s = 0, m = 0;
    for (let j = 0; j < J; j++) { const e = clip.error[f * J + j]; s += e; m = Math.max(m, e); }
    mean[f] = s / J; max[f] = m;
  }
  const top = Math.max(...max, 1e-9), w = canvas.width, h = canvas.height, pad = 18;
  const x = (f) => (F > 1 ? (f / (F - 1)) * (w - 2 * pad) + pad : pad);
  const y = (v) => h - pad - (v / top) * (h - 2 * pad);
  const line = (values, colour) => {
    g.beginPath(); g.strokeStyle = colour;
    values.forEach((v, f) => (f ? g.lineTo(x(f), y(v)) : g.moveTo(x(f), y(v))));
    g.stroke();
  };
  line(max, "#d7301f"); line(mean, "#2a6fdb");
  g.fillStyle = "#555"; g.font = "11px system-ui";
  g.fillText(`joint error (cm): max ${top.toFixed(2)} — red: max over joints, blue: mean`, pad, 12);
  chartImage = g.getImageData(0, 0, w, h);
  chart.x = x;
}

function cursor(f) {
  if (!chartImage) return;
  const canvas = $("chart"), g = canvas.getContext("2d");
  g.putImageData(chartImage, 0, 0);
  g.strokeStyle = "#222"; g.beginPath();
  g.moveTo(chart.x(f), 0); g.lineTo(chart.x(f), canvas.height); g.stroke();
}

// ----- playing -----------------------------------------------------------------------------------
let last = null;
function tick(now) {
  if (state.playing && clip) {
    if (last !== null) state.time += ((now - last) / 1000) * Number($("speed").value);
    let f = Math.floor(state.time * clip.fps);
    if (f >= clip.frames) {
      if ($("loop").checked) { state.time = 0; f = 0; } else { f = clip.frames - 1; setPlaying(false); }
    }
    state.frame = f;
    draw();
  }
  last = now;
  requestAnimationFrame(tick);
}

function setPlaying(on) {
  state.playing = on;
  $("play").textContent = on ? "Pause" : "Play";
}

$("play").addEventListener("click", () => setPlaying(!state.playing));
$("scrub").addEventListener("input", (e) => { state.frame = Number(e.target.value); state.time = state.frame / state.fps; draw(); });
$("layout").addEventListener("change", () => { layout(); draw(); });
controls.addEventListener("change", () => renderer.render(scene, camera));

// ----- coding controls ---------------------------------------------------------------------------
function knobInputs(codec, config) {
  const box = $("knobs");
  box.replaceChildren();
  const current = config && config.codec === codec.id ? config.knobs : {};
  for (const k of codec.knobs) {
    const label = document.createElement("label");
    label.title = k.help;
    label.append(k.name);
    let input;
    const value = k.name in current ? current[k.name] : k.default;
    if (k.choices) {
      input = document.createElement("select");
      for (const c of k.choices) input.append(new Option(String(c), String(c), false, String(c) === String(value)));
    } else if (k.type === "bool") {
      input = document.createElement("input"); input.type = "checkbox"; input.checked = Boolean(value);
    } else {
      input = document.createElement("input");
      input.type = k.type === "str" ? "text" : "number";
      input.step = "any";
      input.value = String(value);
    }
    input.name = k.name;
    input.dataset.kind = k.type;
    label.append(input);
    box.append(label);
  }
}

async function loadCodecs(config) {
  state.codecs = await (await fetch("/api/codecs")).json();
  const select = $("codec");
  for (const c of state.codecs) select.append(new Option(c.baseline ? `${c.id} (baseline)` : c.id, c.id));
  select.value = config ? config.codec : "kinwave";
  knobInputs(state.codecs.find((c) => c.id === select.value), config);
  select.addEventListener("change", () => knobInputs(state.codecs.find((c) => c.id === select.value), null));
}

$("coding").addEventListener("submit", async (event) => {
  event.preventDefault();
  const knobs = {};
  for (const input of $("knobs").querySelectorAll("input, select")) {
    knobs[input.name] = input.type === "checkbox" ? input.checked : input.value;
  }
  const kind = $("target-kind").value;
  const target = kind ? [kind, Number($("target-value").value)] : null;
  $("status").textContent = "encoding…";
  $("coding-error").textContent = "";
  state.ready = false;
  const reply = await fetch("/api/encode", {
    method: "POST", headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ codec: $("codec").value, knobs, target }),
  });
  const data = await reply.json();
  if (!reply.ok) {
    $("coding-error").textContent = data.error;
    $("status").textContent = "ready";
  } else {
    show(data);
    knobInputs(state.codecs.find((c) => c.id === data.config.codec), data.config);
    $("status").textContent = "ready";
  }
  state.ready = true;
});

// ----- live: a relay room ------------------------------------------------------------------------
const avatars = new Map();              // stream id -> Figure
function startLive(params) {
  resize();
  for (const id of ["chart", "transport"]) $(id).hidden = true;
  $("clip-panel").hidden = true;
  $("live-panel").hidden = false;
  $("room-name").textContent = params.get("room");
  state.live = { streams: 0, frames: {}, bits: {} };
  const query = new URLSearchParams({ room: params.get("room"), token: params.get("token") || "",
                                      budget: params.get("budget") || "0", camera: params.get("camera") || "0,1.6,6" });
  const socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/api/live?${query}`);
  socket.onmessage = (event) => {
    const data = JSON.parse(event.data);
    if (data.error) { $("status").textContent = `error: ${data.error}`; state.error = data.error; return; }
    live(data.streams);
  };
  socket.onclose = () => { if (!state.error) $("status").textContent = "disconnected"; };
  $("status").textContent = "watching";
  state.ready = true;
  const loop = () => { renderer.render(scene, camera); requestAnimationFrame(loop); };
  requestAnimationFrame(loop);
}

function live(streams) {
  for (const [id, figure] of avatars) {
    if (!(id in streams)) { scene.remove(figure.group); avatars.delete(id); }
  }
  const rows = [];
  let cx = 0, cz = 0;
  for (const [id, s] of Object.entries(streams)) {
    if (!avatars.has(id)) avatars.set(id, new Figure(scene, s.parents, 0x3b4a6b, 0x2a6fdb));
    avatars.get(id).pose(Float32Array.from(s.positions), 0);
    cx += s.positions[0]; cz += s.positions[2];
    state.live.frames[id] = s.frames; state.live.bits[id] = s.bits_per_second;
    rows.push(`<tr><td>${s.name}</td><td>${s.codec}</td><td>${(s.bits_per_second / 1000).toFixed(2)}</td>` +
              `<td>${s.frames}${s.in_sync ? "" : " (resync)"}</td></tr>`);
  }
  $("avatars").tBodies[0].innerHTML = rows.join("");
  const n = Object.keys(streams).length;
  if (n && !state.live.streams) {          // look at the crowd when it first appears
    controls.target.set(cx / n, 0.9, cz / n);
    camera.position.set(cx / n + 1.5, 2.5, cz / n + 7);
    controls.update();
  }
  state.live.streams = n;
}

// ----- start -------------------------------------------------------------------------------------
async function start() {
  resize();
  const data = await (await fetch("/api/state")).json();
  show(data);
  await loadCodecs(data.config);
  $("status").textContent = "ready";
  state.ready = true;
  requestAnimationFrame(tick);
}
const params = new URLSearchParams(location.search);
if (params.get("room")) startLive(params);
else start().catch((e) => { $("status").textContent = `error: ${e}`; state.error = String(e); });
