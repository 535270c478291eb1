// view.js — the viewer page: camera input, progressive frame requests, figures, selection and
// the editor panel. Everything about the SDF happens on the server (src/view/); this only
// shows frames and sends camera moves and edits.
'use strict';

const FULL = { w: 960, h: 540 };   // the frame at rest
const MOVING = { w: 480, h: 270 }; // while the camera moves
const REST_MS = 150;               // no input for this long: refine to full size

const $ = (id) => document.getElementById(id);
const frame = $('frame');

const cam = { yaw: 30, pitch: 25, distance: 0, target: null, fov: 40 };
const view = { version: 0, selection: -1, axis: null, busy: false, dirty: true,
               full: false, lastInput: 0, figures: {}, frameTimes: [] };
let scene = null;

function frameQuery(size) {
  const q = new URLSearchParams({
    w: size.w, h: size.h, yaw: cam.yaw.toFixed(4), pitch: cam.pitch.toFixed(4),
    distance: cam.distance, fov: cam.fov, shading: $('shading').value,
    shadows: $('shadows').checked ? 1 : 0, grid: $('grid').value, mode: $('mode').value,
    highlight: view.selection,
  });
  if (cam.target) q.set('target', cam.target.map((v) => v.toFixed(6)).join(','));
  return q;
}

function changed() {  // the camera or a setting changed: moving frames until it rests
  view.dirty = true;
  view.full = false;
  view.lastInput = performance.now();
  pump();
}

// One request in flight at a time; coarse while input keeps coming, full size once it rests.
async function pump() {
  if (view.busy) return;
  const resting = performance.now() - view.lastInput >= REST_MS;
  if (!view.dirty && view.full) return;
  if (!view.dirty && !resting) { setTimeout(pump, REST_MS); return; }
  const full = resting;
  const size = full ? FULL : MOVING;
  view.dirty = false;
  view.busy = true;
  try {
    const query = frameQuery(size);
    const res = await fetch('/api/frame?' + query);
    if (!res.ok) { showStatus((await res.json()).error); return; }
    const blob = await res.blob();
    const h = (k) => res.headers.get('X-Sdfprune-' + k);
    if (cam.distance <= 0) cam.distance = parseFloat(h('Distance'));
    if (!cam.target) cam.target = h('Target').split(',').map(parseFloat);
    const url = URL.createObjectURL(blob);
    await new Promise((ok) => { frame.onload = ok; frame.onerror = ok; frame.src = url; });
    URL.revokeObjectURL(frame.dataset.url || '');
    frame.dataset.url = url;
    const now = performance.now();
    view.frameTimes.push(now);
    while (view.frameTimes.length && now - view.frameTimes[0] > 1000) view.frameTimes.shift();
    Object.assign(view.figures, {
      trace: parseFloat(h('Trace-Ms')), evals: parseFloat(h('Evals-Per-Pixel')),
      prune: parseFloat(h('Prune-Ms')), active: parseFloat(h('Near-Active-Avg')),
      activeAll: parseFloat(h('Active-Avg')), w: size.w, h: size.h,
    });
    view.full = full && !view.dirty;
    frame.dataset.width = size.w;
    frame.dataset.height = size.h;
    frame.dataset.version = h('Version');
    frame.dataset.camera = JSON.stringify(cam);
    frame.dataset.query = query.toString();  // everything the frame shows, for tests
    frame.dataset.full = view.full ? '1' : '0';
    showFigures();
    showStatus('');
  } catch (e) {
    showStatus('server unreachable');
  } finally {
    view.busy = false;
    if (view.dirty || !view.full) setTimeout(pump, view.dirty ? 0 : REST_MS);
  }
}

function showFigures() {
  const f = view.figures;
  const naive = $('mode').value === 'naive';
  $('figures').textContent = [
    `nodes ${scene ? scene.nodes : '?'}   primitives ${scene ? scene.primitives : '?'}`,
    naive ? 'naive: the full tree at every step' :
      `active primitives per cell ${f.activeAll.toFixed(3)} (near field ${f.active.toFixed(2)})`,
    naive ? '' : `prune ${f.prune.toFixed(1)} ms (grid ${$('grid').value}³)` +
      (scene && scene.last_update_ms ? `   last edit ${scene.last_update_ms.toFixed(1)} ms` : ''),
    `trace ${f.trace.toFixed(1)} ms at ${f.w}×${f.h}`,
    `node evaluations per pixel ${f.evals.toFixed(1)}`,
    `${view.frameTimes.length} frames per second`,
  ].filter((l) => l).join('\n');
}

function showStatus(text) { $('status').textContent = text; }

async function post(path, body) {
  const res = await fetch(path, { method: 'POST', body: body ? JSON.stringify(body) : undefined,
                                  headers: body ? { 'Content-Type': 'application/json' } : {} });
  const json = await res.json();
  if (!res.ok) { showStatus(json.error); throw new Error(json.error); }
  return json;
}

// Polls the scene: a new version (an edit, or the file changed on disk) is drawn again.
async function pollScene() {
  try {
    const res = await fetch('/api/scene');
    scene = await res.json();
    $('scene-path').textContent = scene.path;
    const err = $('error');
    err.hidden = !scene.error;
    err.textContent = scene.error ? 'the file did not load: ' + scene.error +
      ' (showing the last good scene)' : '';
    $('undo').disabled = !scene.can_undo;
    $('redo').disabled = !scene.can_redo;
    if (scene.version !== view.version) {
      const first = view.version === 0;
      if (first) {  // the server's grid (sdfprune view --grid) is the default choice
        const grid = $('grid');
        if (![...grid.options].some((o) => o.value === String(scene.grid)))
          grid.add(new Option(String(scene.grid)));
        grid.value = String(scene.grid);
      }
      view.version = scene.version;
      if (!first && view.selection >= 0) await showEditor(view.selection);
      changed();
    }
  } catch (e) {
    showStatus('server unreachable');
  }
  setTimeout(pollScene, 500);
}

// ---- camera input ---------------------------------------------------------------------------
function basis() {
  const y = cam.yaw * Math.PI / 180, p = cam.pitch * Math.PI / 180;
  const back = [Math.sin(y) * Math.cos(p), Math.sin(p), Math.cos(y) * Math.cos(p)];
  const right = [Math.cos(y), 0, -Math.sin(y)];
  const up = [back[1] * right[2] - back[2] * right[1], back[2] * right[0] - back[0] * right[2],
              back[0] * right[1] - back[1] * right[0]];
  return { right, up: up.map((v) => -v) };
}

let drag = null;
frame.addEventListener('contextmenu', (e) => e.preventDefault());
frame.addEventListener('pointerdown', (e) => {
  frame.setPointerCapture(e.pointerId);
  drag = { x: e.clientX, y: e.clientY, moved: 0, button: e.button, shift: e.shiftKey,
           start: null };
  if (view.axis && view.selection >= 0) {
    const f = currentFields();
    drag.start = f ? f['translate.' + view.axis] : null;
  }
});
frame.addEventListener('pointermove', (e) => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag.moved += Math.abs(e.movementX) + Math.abs(e.movementY);
  if (drag.moved < 4) return;
  if (drag.start !== null && drag.start !== undefined) {  // move the selection along an axis
    const scale = (cam.distance || 1) * 0.0025;
    const b = basis();
    const a = { x: 0, y: 1, z: 2 }[view.axis];
    const along = dx * b.right[a] - dy * b.up[a];
    queueEdit({ ['translate.' + view.axis]: drag.start + along * scale });
    return;
  }
  drag.x = e.clientX;
  drag.y = e.clientY;
  if (drag.button === 2 || drag.shift) {  // pan
    const b = basis(), s = (cam.distance || 1) * 0.0015;
    cam.target = cam.target.map((t, i) => t - (b.right[i] * dx - b.up[i] * dy) * s);
  } else {  // orbit
    cam.yaw -= dx * 0.3;
    cam.pitch = Math.max(-89, Math.min(89, cam.pitch + dy * 0.3));
  }
  changed();
});
frame.addEventListener('pointerup', (e) => {
  if (drag && drag.moved < 4 && e.button === 0) select(e);
  drag = null;
});
frame.addEventListener('wheel', (e) => {
  e.preventDefault();
  if (!cam.distance) return;
  const k = e.ctrlKey ? 0.01 : 0.0015;  // ctrlKey: a touchpad's pinch
  cam.distance = Math.max(1e-4, cam.distance * Math.exp(e.deltaY * k));
  changed();
}, { passive: false });

// ---- selection and editing ------------------------------------------------------------------
async function select(e) {
  const r = frame.getBoundingClientRect();
  const x = Math.floor((e.clientX - r.left) / r.width * FULL.w);
  const y = Math.floor((e.clientY - r.top) / r.height * FULL.h);
  const q = frameQuery(FULL);
  q.set('x', x);
  q.set('y', y);
  const res = await fetch('/api/pick?' + q, { method: 'POST' });
  const json = await res.json();
  if (!res.ok) { showStatus(json.error); return; }
  if (!json.hit) {
    view.selection = -1;
    $('editor').hidden = true;
    $('editor').dataset.primitive = '';
  } else {
    view.selection = json.selection.primitive;
    fillEditor(json.selection);
  }
  changed();
}

function currentFields() {
  const out = {};
  for (const input of document.querySelectorAll('#editor-fields input'))
    out[input.dataset.field] = parseFloat(input.value);
  return out;
}

function fillEditor(sel) {
  const ed = $('editor');
  ed.hidden = false;
  ed.dataset.primitive = sel.primitive;
  $('editor-title').textContent = `${sel.kind} #${sel.primitive} (node ${sel.node})`;
  const form = $('editor-fields');
  form.textContent = '';
  for (const f of sel.fields) {
    const label = document.createElement('label');
    label.textContent = f.name;
    const input = document.createElement('input');
    input.type = 'number';
    input.step = 'any';
    input.value = +f.value.toPrecision(7);
    input.dataset.field = f.name;
    input.addEventListener('change', () => {
      const v = parseFloat(input.value);
      if (Number.isFinite(v)) queueEdit({ [f.name]: v });
    });
    label.appendChild(input);
    form.appendChild(label);
  }
}

async function showEditor(primitive) {
  const res = await fetch('/api/primitive?id=' + primitive);
  if (res.ok) fillEditor(await res.json());
}

// Edits go one at a time; while one is in flight only the latest values wait.
let pendingEdit = null, editing = false;
async function queueEdit(values) {
  pendingEdit = Object.assign(pendingEdit || {}, values);
  if (editing) return;
  editing = true;
  try {
    while (pendingEdit) {
      const set = pendingEdit;
      pendingEdit = null;
      try {
        const r = await post('/api/edit', { primitive: view.selection, set });
        view.version = r.version;
        if (scene) scene.last_update_ms = r.update_ms;
        changed();
      } catch (e) { break; }
    }
    await showEditor(view.selection);
  } finally {
    editing = false;
  }
}

for (const axis of ['x', 'y', 'z']) {
  $('axis-' + axis).addEventListener('click', () => {
    view.axis = view.axis === axis ? null : axis;
    for (const b of document.querySelectorAll('#axes button'))
      b.classList.toggle('on', b.dataset.axis === view.axis);
  });
}

async function history(path) {
  try {
    const r = await post(path);
    if (r.version) view.version = r.version;
    if (view.selection >= 0) await showEditor(view.selection);
    changed();
  } catch (e) { /* shown in the status line */ }
}
$('undo').addEventListener('click', () => history('/api/undo'));
$('redo').addEventListener('click', () => history('/api/redo'));
$('save').addEventListener('click', async () => {
  try { const r = await post('/api/save'); showStatus('saved ' + r.saved); } catch (e) {}
});
document.addEventListener('keydown', (e) => {
  if (!(e.ctrlKey || e.metaKey) || e.key.toLowerCase() !== 'z') return;
  e.preventDefault();
  history(e.shiftKey ? '/api/redo' : '/api/undo');
});
for (const id of ['shading', 'shadows', 'grid', 'mode']) $(id).addEventListener('change', changed);

pollScene();
