// The drive page: shows the three cameras, sends the person's ramped input, records, takes
// over, replays. Protocol: oasis_torchrl/web/messages.py (to the server), frames.py (frames).
"use strict";

const RAMP = { throttleUp: 2.0, throttleBack: 3.0, steerUp: 2.5, steerBack: 4.0 };
const KEEPALIVE_MS = 100;
const LATENCY_SAMPLES = 200;
const DRIVING_KEYS = {
  KeyW: "up", ArrowUp: "up", KeyS: "down", ArrowDown: "down",
  KeyA: "left", ArrowLeft: "left", KeyD: "right", ArrowRight: "right",
};
const PAD = { record: 0, discard: 1, newScene: 2, takeover: 3, brake: 6, throttle: 7 };
const DEAD_ZONE = 0.08;

// What tests and tools read.
const page = (window.oasisPage = {
  status: null, latencies: [], framesShown: 0, errors: [], replayed: 0, connected: false,
});

const query = window.location.search;
const held = new Set();
const input = { throttle: 0, steering: 0 };
let seq = 0;
let lastSent = { throttle: NaN, steering: NaN, at: 0 };
let pendingKeys = []; // {seq, t}: key events waiting for their first frame
let frameQueue = [];
let framePeriod = 50;
let replaying = false;
let socket = null;
const padPressed = new Set();

function $(id) { return document.getElementById(id); }

function connect() {
  const scheme = window.location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${window.location.host}/ws${query}`);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => { page.connected = true; badge("connection", "connected", "ok"); };
  socket.onclose = () => {
    page.connected = false;
    badge("connection", "disconnected: reload to reconnect", "bad");
  };
  socket.onmessage = (event) => {
    if (typeof event.data === "string") onJson(JSON.parse(event.data));
    else onFrame(event.data);
  };
}

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
}

function badge(id, text, kind) {
  const el = $(id);
  el.textContent = text;
  el.className = "badge" + (kind ? " " + kind : "");
}

function say(text) { $("message").textContent = text; }

// -- messages from the server ---------------------------------------------------------------

function onJson(message) {
  if (message.type === "status") showStatus(message);
  else if (message.type === "error") {
    page.errors.push(message.error);
    say(`refused: ${message.error}: ${message.message}`);
  } else if (message.type === "done") say(`${message.request}: done`);
  else if (message.type === "replay_done") {
    replaying = false;
    pendingKeys = []; // keys pressed during a replay had no live frame to reach
    say(`replayed episode ${message.episode} (${message.frames} frames)`);
  }
}

function onFrame(buffer) {
  const view = new DataView(buffer);
  const length = view.getUint32(0);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
  if (!header.replay && replaying) return;
  let offset = 4 + length;
  const images = header.cameras.map((camera, i) => {
    const blob = new Blob([new Uint8Array(buffer, offset, header.sizes[i])], { type: "image/jpeg" });
    offset += header.sizes[i];
    return { camera, blob };
  });
  frameQueue.push({ header, images });
  if (frameQueue.length > 8) frameQueue = frameQueue.slice(-4); // behind: catch up
}

async function showFrames() {
  const next = frameQueue.shift();
  if (next) {
    const bitmaps = await Promise.all(next.images.map((image) => createImageBitmap(image.blob)));
    next.images.forEach((image, i) => {
      const canvas = $(`cam-${image.camera}`);
      if (!canvas) return;
      if (canvas.width !== bitmaps[i].width) {
        canvas.width = bitmaps[i].width;
        canvas.height = bitmaps[i].height;
      }
      canvas.getContext("2d").drawImage(bitmaps[i], 0, 0);
    });
    page.framesShown += 1;
    if (next.header.replay) page.replayed += 1;
    else measureLatency(next.header.seq);
  }
  setTimeout(showFrames, frameQueue.length > 4 ? framePeriod / 2 : framePeriod);
}

function measureLatency(appliedSeq) {
  const now = performance.now();
  const reached = pendingKeys.filter((key) => key.seq <= appliedSeq);
  pendingKeys = pendingKeys.filter((key) => key.seq > appliedSeq);
  for (const key of reached) page.latencies.push(now - key.t);
  if (page.latencies.length > LATENCY_SAMPLES) page.latencies.splice(0, page.latencies.length - LATENCY_SAMPLES);
  if (page.latencies.length) {
    const sorted = [...page.latencies].sort((a, b) => a - b);
    const at = (q) => sorted[Math.min(sorted.length - 1, Math.floor(q * sorted.length))];
    $("latency").textContent = `p50 ${at(0.5).toFixed(0)} ms, p95 ${at(0.95).toFixed(0)} ms`;
  }
}

function known(value, digits, unit) {
  return value === null || value === undefined ? "n/a" : `${value.toFixed(digits)} ${unit}`;
}

function showStatus(status) {
  page.status = status;
  framePeriod = status.period_ms / 4;
  $("speed").textContent = known(status.speed, 1, "m/s");
  $("progress").textContent = known(status.progress, 1, "m");
  $("chunk").textContent = status.chunk;
  $("late").textContent = status.late;
  $("saved").textContent = status.saved;
  $("risk").textContent = status.risk === null ? "n/a" : status.risk.toFixed(2);
  $("risk-bar").style.width = `${100 * (status.risk || 0)}%`;
  $("episode").textContent = status.recording ? `${status.episode_steps} chunks` : "-";
  badge("record-state", status.recording ? "recording" : "not recording", status.recording ? "rec" : "");
  if (status.policy) badge("driver", status.human ? "person drives" : "policy drives", status.human ? "" : "policy");
  else badge("driver", "person drives", "");
  if (status.episode_saved) say(`episode saved (${status.saved} this session)`);
}

// -- input ------------------------------------------------------------------------------------

function approach(value, target, up, back, dt) {
  const rate = target === 0 || Math.sign(target) !== Math.sign(value) ? back : up;
  const step = rate * dt;
  return Math.abs(target - value) <= step ? target : value + Math.sign(target - value) * step;
}

function padState() {
  const pads = navigator.getGamepads ? [...navigator.getGamepads()].filter(Boolean) : [];
  if (!pads.length) return null;
  const pad = pads[0];
  const axis = (v) => (Math.abs(v) < DEAD_ZONE ? 0 : v);
  const button = (i) => (pad.buttons[i] ? pad.buttons[i].value : 0);
  const throttle = button(PAD.throttle) - button(PAD.brake);
  for (const [name, index] of Object.entries(PAD)) {
    const down = pad.buttons[index] && pad.buttons[index].pressed;
    if (down && !padPressed.has(index)) { padPressed.add(index); onPadButton(name); }
    if (!down) padPressed.delete(index);
  }
  return { throttle, steering: axis(pad.axes[0] || 0) };
}

function onPadButton(name) {
  if (name === "record") toggleRecord();
  else if (name === "discard") send({ type: "record", command: "discard" });
  else if (name === "takeover") toggleTakeover();
  else if (name === "newScene") send({ type: "reset" });
}

const TICK_MS = 1000 / 60;
let lastTick = performance.now();
function tick() {
  const now = performance.now();
  const dt = Math.min((now - lastTick) / 1000, 0.1);
  lastTick = now;
  const pad = padState();
  if (pad && (pad.throttle !== 0 || pad.steering !== 0) && held.size === 0) {
    input.throttle = pad.throttle; // analog: no ramp
    input.steering = pad.steering;
  } else rampKeys(dt);
  sendInput(false);
  showInput();
}

// Held keys move the input toward full lock at a rate, and back to zero when released.
function rampKeys(dt) {
  const throttleTarget = (held.has("up") ? 1 : 0) - (held.has("down") ? 1 : 0);
  const steeringTarget = (held.has("right") ? 1 : 0) - (held.has("left") ? 1 : 0);
  input.throttle = approach(input.throttle, throttleTarget, RAMP.throttleUp, RAMP.throttleBack, dt);
  input.steering = approach(input.steering, steeringTarget, RAMP.steerUp, RAMP.steerBack, dt);
}

function sendInput(force) {
  const throttle = Math.round(input.throttle * 100) / 100;
  const steering = Math.round(input.steering * 100) / 100;
  const now = performance.now();
  const changed = throttle !== lastSent.throttle || steering !== lastSent.steering;
  if (!force && !changed && now - lastSent.at < KEEPALIVE_MS) return;
  if (!force && !changed && throttle === 0 && steering === 0) return;
  seq += 1;
  send({ type: "control", throttle, steering, seq });
  lastSent = { throttle, steering, at: now };
}

function showInput() {
  for (const name of ["throttle", "steering"]) {
    const value = input[name];
    $(name).textContent = value.toFixed(2);
    const bar = $(`${name}-bar`);
    bar.style.left = `${50 + Math.min(0, value) * 50}%`;
    bar.style.width = `${Math.abs(value) * 50}%`;
  }
}

function toggleRecord() {
  const recording = page.status && page.status.recording;
  send({ type: "record", command: recording ? "stop" : "start" });
}

// The car crashed: the episode ends at the next chunk, saved with that chunk marked.
function markCrash() {
  send({ type: "record", command: "crash" });
}

function toggleTakeover() {
  send({ type: "takeover", human: !(page.status && page.status.human) });
}

function replay() {
  const episode = parseInt($("replay-episode").value, 10);
  replaying = true;
  frameQueue = [];
  pendingKeys = [];
  say(`replaying episode ${episode}`);
  send({ type: "replay", episode });
}

const COMMAND_KEYS = {
  KeyR: toggleRecord,
  KeyX: () => send({ type: "record", command: "discard" }),
  KeyC: markCrash,
  Backspace: () => send({ type: "record", command: "discard" }),
  KeyT: toggleTakeover,
  KeyN: () => send({ type: "reset" }),
  KeyP: replay,
};

document.addEventListener("keydown", (event) => {
  if (event.target.tagName === "INPUT") return;
  const direction = DRIVING_KEYS[event.code];
  if (direction) {
    event.preventDefault();
    if (!held.has(direction)) {
      held.add(direction);
      pendingKeys.push({ seq: seq + 1, t: performance.now() });
      keyNow();
    }
  } else if (COMMAND_KEYS[event.code] && !event.repeat) {
    event.preventDefault();
    COMMAND_KEYS[event.code]();
  }
});

document.addEventListener("keyup", (event) => {
  const direction = DRIVING_KEYS[event.code];
  if (direction && held.delete(direction)) {
    pendingKeys.push({ seq: seq + 1, t: performance.now() });
    keyNow();
  }
});

window.addEventListener("blur", () => held.clear()); // a key released elsewhere

// A key event sends its first step of input at once, not at the next tick.
function keyNow() {
  rampKeys(TICK_MS / 1000);
  sendInput(true);
}

$("record").onclick = toggleRecord;
$("discard").onclick = () => send({ type: "record", command: "discard" });
$("crash").onclick = markCrash;
$("takeover").onclick = toggleTakeover;
$("reset").onclick = () => send({ type: "reset" });
$("replay").onclick = replay;

connect();
setInterval(tick, TICK_MS); // not requestAnimationFrame: it stops in a hidden tab
showFrames();
