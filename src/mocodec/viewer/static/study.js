// The study page: DSCQS (reference and coded clip as A and B, A B A B, then a 1-5 score each)
// and the 2AFC staircase (original and distorted side by side, pick the smoother). The server
// chooses the order and keeps the answers; this page only plays and asks.
import * as THREE from "three";
import { Body, f32 } from "/shared/body.js";
import { Figure } from "/static/figure.js";

const $ = (id) => document.getElementById(id);
const state = { ready: false, phase: "loading", index: 0, saved: null };
window.studyState = state;             // read by the browser tests

const view = $("view");
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
view.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xfafafa);
scene.add(new THREE.GridHelper(40, 40, 0x999999, 0xdddddd));
scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(3, 6, 4);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 200);
function resize() {
  renderer.setSize(view.clientWidth, view.clientHeight);
  camera.aspect = view.clientWidth / view.clientHeight;
  camera.updateProjectionMatrix();
}

let figures = [], showing = 0;          // `showing` counts plays: an older play's loop stops
function clear() { figures.forEach((f) => scene.remove(f.group)); figures = []; showing++; }

// a clip of the trial: joint positions and orientations, from base64
const clipOf = (c) => ({ positions: f32(c.positions), quats: f32(c.quats) });

// play `clips` side by side once, as bodies or stick figures (the study's rendering, which the
// server records with each trial); resolves when done (or loops until stopped)
function play(trial, clips, loop) {
  clear();
  const offset = 1.2, n = trial.parents.length;
  state.rendering = trial.rendering;
  clips.forEach((_, k) => {
    const fig = trial.rendering === "body" && trial.body ? new Body(scene, trial.body, 0x8a9bb8)
                                           : new Figure(scene, trial.parents, 0x3b4a6b, 0x3b4a6b);
    fig.group.position.x = (k - (clips.length - 1) / 2) * offset;
    figures.push(fig);
  });
  const mine = showing;
  return new Promise((resolve) => {
    let start = null;
    const step = (now) => {
      if (mine !== showing) { resolve(); return; }
      if (start === null) start = now;
      let f = Math.floor(((now - start) / 1000) * trial.fps * trial.speed);
      if (f >= trial.frames) {
        if (!loop || state.phase !== "choosing") { resolve(); return; }
        start = now; f = 0;
      }
      const root = [clips[0].positions[f * n * 3], clips[0].positions[f * n * 3 + 2]];
      clips.forEach((c, k) => { figures[k].group.position.x = (k - (clips.length - 1) / 2) * offset - root[0];
                                figures[k].group.position.z = -root[1]; if (figures[k] instanceof Body) figures[k].pose(c.positions, c.quats, f);
                                else figures[k].pose(c.positions, f); });
      camera.position.set(0, 1.4, 3.6);
      camera.lookAt(0, 0.9, 0);
      renderer.render(scene, camera);
      requestAnimationFrame(step);
    };
    requestAnimationFrame(step);
  });
}

async function next() {
  const trial = await (await fetch("/api/trial")).json();
  if (trial.done) { finish(trial.saved); return; }
  state.index = trial.index;
  $("progress").textContent = trial.total ? `case ${trial.index + 1} of ${trial.total}` : `trial ${trial.index + 1}`;
  $("status").textContent = "";
  state.ready = true;
  if (trial.kind === "dscqs") await dscqs(trial); else await choose(trial);
}

async function dscqs(trial) {
  $("dscqs").hidden = true;
  state.phase = "playing";
  for (const label of trial.sequence) {
    $("showing").textContent = label;
    await play(trial, [clipOf(trial[label])], false);
  }
  $("showing").textContent = "";
  clear();
  renderer.render(scene, camera);
  const scores = {};
  for (const row of document.querySelectorAll(".score-row")) {
    row.querySelectorAll("button").forEach((b) => b.remove());
    for (const [value, name] of Object.entries(trial.scores)) {
      const b = document.createElement("button");
      b.type = "button"; b.textContent = `${value} ${name}`; b.dataset.score = value;
      b.addEventListener("click", () => {
        scores[row.dataset.clip] = Number(value);
        row.querySelectorAll("button").forEach((o) => o.classList.toggle("chosen", o === b));
        $("next").disabled = !("A" in scores && "B" in scores);
      });
      row.append(b);
    }
  }
  $("next").disabled = true;
  $("dscqs").hidden = false;
  state.phase = "scoring";
  await new Promise((resolve) => { $("next").onclick = resolve; });
  $("dscqs").hidden = true;
  await answer({ scores });
}

async function choose(trial) {
  state.phase = "choosing";
  $("choice").hidden = false;
  play(trial, [clipOf(trial.left), clipOf(trial.right)], true);
  const choice = await new Promise((resolve) => {
    $("pick-left").onclick = () => resolve("left");
    $("pick-right").onclick = () => resolve("right");
  });
  state.phase = "answered";
  $("choice").hidden = true;
  await answer({ choice });
}

async function answer(reply) {
  $("status").textContent = "…";
  state.ready = false;
  const r = await fetch("/api/answer", { method: "POST", headers: { "Content-Type": "application/json" },
                                         body: JSON.stringify(reply) });
  const data = await r.json();
  if (!r.ok) { $("status").textContent = `error: ${data.error}`; return; }
  if (data.done) finish(data.saved); else next();
}

function finish(saved) {
  clear();
  state.phase = "done"; state.saved = saved; state.ready = true;
  $("done").hidden = false;
  $("status").textContent = "done";
}

resize();
next().catch((e) => { $("status").textContent = `error: ${e}`; state.error = String(e); });
