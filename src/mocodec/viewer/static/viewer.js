// The mocodec viewer: the original and the decoded motion in sync, the decoded joints coloured
// by their error, the error over time, the numbers, and re-encoding with another codec or knob;
// or, with ?room=R&token=T, every avatar of a relay room live with the bit rate it gets, the page
// joining the relay itself and decoding in the browser (mocodec's JavaScript decoder).
// A clip's joint positions (metres) and orientations come from the server (forward kinematics is
// done there), with the skeleton's mannequin, drawn as a skinned body (or as stick figures).
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { Body, Mannequins, f32 } from "/shared/body.js";
import { Figure } from "/static/figure.js";
import { RelayClient } from "/static/decoder/index.js";

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
scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(3, 6, 4);
scene.add(sun);

// where a point (metres, world) lands on the canvas, in pixels: for the browser tests
state.project = (x, y, z) => {
  const v = new THREE.Vector3(x, y, z).project(camera);
  return [((v.x + 1) / 2) * view.clientWidth, ((1 - v.y) / 2) * view.clientHeight];
};
state.decodedShift = () => (decodedBody ? decodedBody.group.position.x : 0);

function resize() {
  const w = view.clientWidth, h = view.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener("resize", resize);

// ----- the clip ----------------------------------------------------------------------------------
let clip = null, original = null, decoded = null, originalBody = null, decodedBody = null, lastRoot = null;
const BODY = new THREE.Color(0x8a9bb8), DECODED_BODY = new THREE.Color(0xb0b0b0);
const SPACING = 1.2;                   // metres between the two figures side by side

function heat(value, max) {
  const t = max > 0 ? Math.min(value / max, 1) : 0;
  return new THREE.Color().setHSL(0.62 * (1 - t), 0.85, 0.5);
}

function show(data) {
  clip = {
    fps: data.fps, frames: data.frames, joints: data.joints.length, parents: data.parents,
    original: f32(data.original),
    originalQuats: f32(data.original_quats),
    decoded: data.decoded ? f32(data.decoded) : null,
    decodedQuats: data.decoded_quats ? f32(data.decoded_quats) : null,
    error: data.error_cm ? f32(data.error_cm) : null,
  };
  state.frames = clip.frames; state.fps = clip.fps; state.numbers = data.numbers;
  $("clip-name").textContent = data.name;
  $("scrub").max = String(Math.max(clip.frames - 1, 0));
  if (!original) {
    original = new Figure(scene, clip.parents, 0x3b4a6b, 0x3b4a6b);
    decoded = new Figure(scene, clip.parents, 0x555555, 0x2a6fdb);
    if (data.body) {
      originalBody = new Body(scene, data.body, BODY);
      decodedBody = new Body(scene, data.body, DECODED_BODY);
    } else {                              // a skeleton without a bone to build a body on
      $("figures").value = "sticks";
      $("figures").disabled = true;
    }
  }
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
  const side = $("layout").value === "side", bodies = $("figures").value === "bodies";
  decoded.group.position.set(side ? SPACING : 0, 0, 0);
  decoded.lines.material.color.set(side ? 0x555555 : 0xd7301f);
  original.group.visible = !bodies;
  decoded.group.visible = !bodies && Boolean(clip.decoded);
  lastRoot = null;
  if (!originalBody) return;
  decodedBody.group.position.copy(decoded.group.position);
  originalBody.group.visible = bodies;
  decodedBody.group.visible = bodies && Boolean(clip.decoded);
  // overlaid, the original body is a ghost around the decoded one
  originalBody.material.transparent = bodies && !side && Boolean(clip.decoded);
  originalBody.material.opacity = originalBody.material.transparent ? 0.35 : 1;
  originalBody.material.depthWrite = !originalBody.material.transparent;
  originalBody.material.needsUpdate = true;
}

function draw() {
  if (!clip) return;
  const f = Math.min(state.frame, clip.frames - 1);
  original.pose(clip.original, f);
  originalBody?.pose(clip.original, clip.originalQuats, f);
  if (clip.decoded) {
    decoded.pose(clip.decoded, f);
    decodedBody?.pose(clip.decoded, clip.decodedQuats, f);
    const max = state.numbers ? state.numbers.max_joint_error_cm : 1;
    const row = clip.error.subarray(f * clip.joints, (f + 1) * clip.joints);
    const colours = Array.from(row, (e) => heat(e, max));
    decoded.colour(colours);
    decodedBody?.colour(colours);
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
$("figures").addEventListener("change", () => { layout(); draw(); });
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

// ----- live: a relay room, decoded in this page -------------------------------------------------
const RATE_WINDOW_S = 4;                // seconds over which an avatar's bit rate is measured
const CAMERA_EVERY_S = 1;               // how often the relay may hear where this viewer looks from
const TABLE_EVERY_S = 0.25;             // how often the table of avatars is redrawn
const FRAME_TIMES = 240;                // animation frames whose JavaScript time the page keeps (tests, benchmarks)
const avatars = new Map();              // stream id -> its stick figure, body and rotations
async function startLive(params) {
  resize();
  for (const id of ["chart", "transport"]) $(id).hidden = true;
  $("clip-panel").hidden = true;
  $("live-panel").hidden = false;
  $("room-name").textContent = params.get("room");
  if (params.get("figures") === "sticks") $("figures").value = "sticks";  // ?figures=sticks: no bodies
  // ?render=0: decode and pose (with the skin matrices), but draw nothing (measures the page's
  // JavaScript alone, as benchmarks/bench_live_page.py does, free of a software renderer's cost)
  const draws = params.get("render") !== "0";
  state.live = { streams: 0, frames: {}, bits: {}, others: {}, frameMs: [], partsMs: [], poseMs: 0, bodies: 0 };
  const { relay } = await (await fetch("/api/relay")).json();
  if (!relay) throw new Error("this viewer has no relay: start it with --relay ws://HOST:PORT");
  const client = new RelayClient(relay, {
    room: params.get("room"), token: params.get("token") || "", budget: Number(params.get("budget") || 0),
    camera: (params.get("camera") || "0,1.6,6").split(",").map(Number),
  });
  await client.connect();
  state.live.client = client;
  $("status").textContent = "watching, decoded in this page";
  state.ready = true;
  const history = [];                   // [seconds, {stream: bytes}]
  let cameraAt = 0, cameraSent = "", tableAt = 0, decoded = 0;
  const loop = () => {
    const now = performance.now() / 1000;
    const bytes = {};
    for (const [id, a] of [...client.avatars, ...client.others]) bytes[id] = a.bytes;
    history.push([now, bytes]);
    while (history.length > 2 && now - history[0][0] > RATE_WINDOW_S) history.shift();
    drawRoom(client, now);
    if (now - tableAt > TABLE_EVERY_S) {
      tabulate(client, history);
      tableAt = now;
    }
    const where = camera.position.toArray().map((v) => Math.round(v * 100) / 100);
    if (now - cameraAt > CAMERA_EVERY_S && String(where) !== cameraSent) {
      client.send({ camera: where });
      [cameraAt, cameraSent] = [now, String(where)];
    }
    const drawn = performance.now();
    if (draws) renderer.render(scene, camera);
    // this frame's JavaScript: decoding since the last one, posing (with the skin matrices), drawing
    const parts = [client.decodeMs - decoded, state.live.poseMs, performance.now() - drawn];
    decoded = client.decodeMs;
    state.live.frameMs.push(parts[0] + parts[1] + parts[2]);
    state.live.partsMs.push(parts);     // decoding, posing (with the skin matrices), drawing
    if (state.live.frameMs.length > FRAME_TIMES) { state.live.frameMs.shift(); state.live.partsMs.shift(); }
    requestAnimationFrame(loop);
  };
  requestAnimationFrame(loop);
}

// Every avatar's pose now (joint positions in metres and global rotations, played out by its
// jitter buffer), as a body (its mannequin, asked of the server once per kind of skeleton, at a
// level of detail by its distance from the camera: /shared/body.js) or as a stick figure.
const mannequins = new Mannequins("/api/mannequin");

function drawRoom(client, now) {
  const started = performance.now();
  for (const [id, shown] of avatars) {
    const a = client.avatars.get(id);
    if (!a || a.decoder.ended) {
      scene.remove(shown.figure.group);
      if (shown.body) scene.remove(shown.body.group);
      avatars.delete(id);
    }
  }
  const bodies = $("figures").value === "bodies";
  let cx = 0, cz = 0, shown = 0;
  for (const [id, a] of client.avatars) {
    const J = a.skeleton.joints.length;
    if (!avatars.has(id)) {
      avatars.set(id, { figure: new Figure(scene, Array.from(a.skeleton.parents), 0x3b4a6b, 0x2a6fdb), body: null,
                        wxyz: new Float64Array(J * 4), key: null });
    }
    const it = avatars.get(id);
    const pose = a.decoder.ended ? null : a.pose(now, it.wxyz);
    if (!pose) continue;
    const levels = bodies ? mannequins.of(a, it) : null;
    if (levels && !it.body) it.body = new Body(scene, levels, 0x8a9bb8);
    it.figure.group.visible = !(levels && it.body);
    if (it.body) it.body.group.visible = Boolean(levels);
    if (levels && it.body) {
      it.body.follow(pose, it.wxyz, camera);
    } else {
      it.figure.pose(pose, 0);
    }
    cx += pose[0]; cz += pose[2]; shown += 1;
  }
  if (shown && !state.live.streams) {     // look at the crowd when it first appears
    controls.target.set(cx / shown, 0.9, cz / shown);
    camera.position.set(cx / shown + 1.5, 2.5, cz / shown + 7);
    controls.update();
  }
  state.live.streams = shown;
  state.live.bodies = [...avatars.values()].filter((it) => it.body && it.body.group.visible).length;
  state.live.poseMs = performance.now() - started;
}

// The table of avatars: each one's codec, frames and bit rate over the window of `history`.
function tabulate(client, history) {
  const [[t0, first], [t1, last]] = [history[0], history.at(-1)];
  const rate = (id) => (8 * ((last[id] ?? 0) - (first[id] ?? 0))) / Math.max(t1 - t0, 1e-3);
  const rows = [];
  for (const [id, a] of client.avatars) {
    if (a.decoder.ended) continue;
    state.live.frames[id] = a.frames; state.live.bits[id] = rate(id);
    rows.push(`<tr><td>${escape(a.name || `stream ${id}`)}</td><td>${escape(a.codec)}</td><td>${(rate(id) / 1000).toFixed(2)}</td>` +
              `<td>${a.frames}${a.decoder.inStep ? "" : " (resync)"}</td></tr>`);
  }
  for (const [id, o] of client.others) {
    state.live.others[id] = o.codec;
    rows.push(`<tr class="undecodable"><td>${escape(o.name || `stream ${id}`)}</td><td>${escape(o.codec)}</td>` +
              `<td>${(rate(id) / 1000).toFixed(2)}</td><td>not decodable in the browser</td></tr>`);
  }
  $("avatars").tBodies[0].innerHTML = rows.join("");
}

function escape(text) {
  return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
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
const fail = (e) => { $("status").textContent = `error: ${e.message ?? e}`; state.error = String(e.message ?? e); };
(params.get("room") ? startLive(params) : start()).catch(fail);
