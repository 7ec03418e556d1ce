// twinforge twin editor: wires the side panel, the 3D view and the server.
// The page never edits its spec on its own: every edit is a POST of the whole
// edited spec, and the page's state becomes whatever the server answers.
import { api, ApiError, busy } from './api.js';
import { Viewer, partColor } from './viewer.js';
import {
  $, LocalError, num, nums, setNum, setNums, setExact, fillSelect, renderList,
  setStatus, setDirty, showError, clearError,
} from './panels.js';

const BOX_C = ['box-cx', 'box-cy', 'box-cz'];
const BOX_S = ['box-sx', 'box-sy', 'box-sz'];
const BOX_R = ['box-roll', 'box-pitch', 'box-yaw'];
const J_AXIS = ['joint-axis-x', 'joint-axis-y', 'joint-axis-z'];
const J_ORIGIN = ['joint-origin-x', 'joint-origin-y', 'joint-origin-z'];
const S_POS = ['site-x', 'site-y', 'site-z'];

const state = {
  twin: null,        // last /api/twin payload
  spec: null,        // = twin.spec
  selected: null,    // selected part name
  touched: { joint: false, site: false }, // tool moved/edited by the person since its last add
  editing: { joint: null, site: null },   // entry picked in the list, for "Update"
};

const viewer = new Viewer($('view'), {
  onPickPart: (name) => select(name),
  onPickTool: (tool) => viewer.attachTool(tool),
  onToolMoved: toolMoved,
});
if (viewer.glError) showError(viewer.glError);
window.__twinforge = { viewer, state, screenPointOf: (name) => viewer.screenPointOf(name) };

// ---- request sequencing -----------------------------------------------------
// Actions run one at a time; the page is busy for the whole action (the POST
// and the part mesh refetch that follows it).
let chain = Promise.resolve();
function serial(fn) {
  const run = chain.then(async () => {
    busy(+1);
    try {
      return await fn();
    } finally {
      busy(-1);
    }
  });
  chain = run.catch(() => {});
  return run;
}

// Run an action; show its error. After a server error, re-read the server's
// state so the page matches it.
function action(fn) {
  return () => serial(async () => {
    try {
      await fn();
    } catch (e) {
      showError(e.message);
      if (e instanceof ApiError) await resync();
      else if (!(e instanceof LocalError)) console.error(e);
    }
  });
}

async function resync() {
  try {
    const t = await api.twin();
    const changed = JSON.stringify(t.spec) !== JSON.stringify(state.spec);
    applyTwin(t);
    if (changed) {
      viewer.clearExport();
      await refreshParts();
    }
  } catch {
    // the error shown already says what went wrong
  }
}

// POST an edited copy of the spec; on success the answer becomes the state.
async function postSpec(mutate, msg, { selectAfter } = {}) {
  const spec = structuredClone(state.spec);
  mutate(spec);
  const t = await api.setSpec(spec);
  clearError();
  if (selectAfter !== undefined) state.selected = selectAfter;
  applyTwin(t);
  viewer.clearExport();
  await refreshParts();
  setStatus(`ready · ${msg}`);
}

// ---- state from the server -----------------------------------------------------
function applyTwin(t) {
  state.twin = t;
  state.spec = t.spec;
  const spec = state.spec;
  spec.parts ??= [];
  spec.joints ??= [];
  spec.sites ??= [];
  $('twin-name').textContent = t.name || spec.name || '';
  document.title = `twinforge · ${t.name || spec.name || 'twin'}`;
  setDirty(!!t.dirty);
  $('undo').disabled = !t.can_undo;

  const partNames = spec.parts.map((p) => p.name);
  if (state.selected && !partNames.includes(state.selected)) state.selected = null;
  fillSelect('joint-parent', [...partNames, 'world']);
  fillSelect('joint-child', partNames);
  fillSelect('site-part', [...partNames, 'world']);
  for (const k of ['joint', 'site']) {
    const list = k === 'joint' ? spec.joints : spec.sites;
    if (state.editing[k] && !list.some((x) => x.name === state.editing[k])) setEditing(k, null);
  }
  renderLists();
  fillPartPanel();
  viewer.setSelected(state.selected);
  viewer.setAnnotations(spec);
}

function renderLists() {
  const spec = state.spec;
  renderList('parts', 'part', spec.parts, {
    selected: state.selected,
    swatch: (p) => `#${partColor(spec.parts.indexOf(p)).toString(16).padStart(6, '0')}`,
    note: (p) => `${p.fixed ? 'fixed' : `${p.mass} kg`} · ${(p.cuts || []).length} cut(s)`,
    onClick: select,
  });
  renderList('joints', 'joint', spec.joints, {
    selected: state.editing.joint,
    note: (j) => `${j.type} ${j.parent} → ${j.child}`,
    onClick: pickJoint,
    onDelete: (name) => action(() => postSpec((s) => {
      s.joints = s.joints.filter((j) => j.name !== name);
    }, `deleted joint ${name}`))(),
  });
  renderList('sites', 'site', spec.sites, {
    selected: state.editing.site,
    note: (s) => `on ${s.part}`,
    onClick: pickSite,
    onDelete: (name) => action(() => postSpec((s) => {
      s.sites = s.sites.filter((x) => x.name !== name);
    }, `deleted site ${name}`))(),
  });
}

// Fetch the cut mesh of every part whose mesh, cuts or colour changed since it was drawn
// (newest request wins): setting a mass or adding a site refetches nothing.
let partGen = 0;
const drawn = new Map(); // part name -> what its drawn mesh was made from
async function refreshParts() {
  const gen = ++partGen;
  const parts = state.spec.parts;
  const keyOf = (p, i) => JSON.stringify([p.mesh, p.cuts || [], i]);
  const results = await Promise.all(parts.map((p, i) => (drawn.get(p.name) === keyOf(p, i)
    ? Promise.resolve({ p, unchanged: true })
    : api.part(p.name).then((data) => ({ p, data }), (err) => ({ p, err })))));
  if (gen !== partGen) return;
  const errors = [];
  results.forEach(({ p, data, err, unchanged }, i) => {
    if (unchanged) return;
    if (err) {
      drawn.delete(p.name);
      errors.push(`${p.name}: ${err.message}`);
    } else {
      viewer.setPart(p.name, data, partColor(i));
      drawn.set(p.name, keyOf(p, i));
    }
  });
  for (const name of [...drawn.keys()]) if (!parts.some((p) => p.name === name)) drawn.delete(name);
  viewer.keepParts(parts.map((p) => p.name));
  viewer.setSelected(state.selected);
  if (errors.length) showError(`part meshes: ${errors.join('; ')}`);
}

// ---- selection and the part panel ------------------------------------------------
function select(name) {
  state.selected = name;
  viewer.setSelected(name);
  for (const li of $('parts').children) li.classList.toggle('selected', li.dataset.part === name);
  fillPartPanel();
  if (!name) return;
  // Tool defaults follow the selection until the person moves that tool.
  $('cut-name').value = `${name}_cut`;
  const c = partCentre(name);
  if (!state.touched.joint) {
    $('joint-child').value = name;
    setNums(J_ORIGIN, c);
    syncJointTool();
  }
  if (!state.touched.site) {
    $('site-part').value = name;
    setNums(S_POS, c);
    syncSiteTool();
  }
}

function fillPartPanel() {
  const p = state.spec?.parts.find((x) => x.name === state.selected);
  $('part-panel').disabled = !p;
  $('part-selected').textContent = p ? p.name : '(none)';
  $('part-name').value = p ? p.name : '';
  $('part-mass').value = p ? p.mass : '';
  $('part-friction').value = p ? p.friction : '';
  $('part-fixed').checked = !!p?.fixed;
}

function partCentre(name) {
  const b = viewer.partBox(name);
  return b ? b.getCenter(b.min.clone()).toArray() : viewer.orbit.target.toArray();
}

function findPart(spec, name) {
  const p = spec.parts.find((x) => x.name === name);
  if (!p) throw new LocalError(`no part named '${name}'`);
  return p;
}

function requireSelected() {
  if (!state.selected) throw new LocalError('select a part first (click it in the view or in the list)');
  return state.selected;
}

$('apply-part').addEventListener('click', action(async () => {
  const from = requireSelected();
  const to = $('part-name').value.trim();
  if (!to) throw new LocalError('part name: empty');
  const mass = num('part-mass');
  const friction = num('part-friction');
  const fixed = $('part-fixed').checked;
  await postSpec((spec) => {
    const p = findPart(spec, from);
    Object.assign(p, { mass, friction, fixed });
    if (to !== from) {
      // a rename carries the references along
      p.name = to;
      for (const j of spec.joints) {
        if (j.parent === from) j.parent = to;
        if (j.child === from) j.child = to;
      }
      for (const s of spec.sites) if (s.part === from) s.part = to;
    }
  }, to !== from ? `renamed ${from} → ${to}` : `updated ${to}`, { selectAfter: to });
}));

$('delete-part').addEventListener('click', action(async () => {
  const name = requireSelected();
  await postSpec((spec) => {
    spec.parts = spec.parts.filter((p) => p.name !== name);
    spec.joints = spec.joints.filter((j) => j.parent !== name && j.child !== name);
    spec.sites = spec.sites.filter((s) => s.part !== name);
  }, `deleted part ${name}`, { selectAfter: null });
}));

// ---- cut tool -------------------------------------------------------------------
function readBox() {
  return { center: nums(BOX_C), size: nums(BOX_S), euler: nums(BOX_R), shape: 'box', hidden: false };
}

function syncCutTool() {
  try {
    const b = readBox();
    viewer.setCutBox(b);
  } catch {
    // a half-typed number: leave the box where it is
  }
}

$('add-box').addEventListener('click', action(async () => {
  const name = requireSelected();
  const b = viewer.partBox(name);
  if (!b) throw new LocalError(`part '${name}' has no triangles to place a box on`);
  setNums(BOX_C, b.getCenter(b.min.clone()).toArray());
  setNums(BOX_S, b.getSize(b.min.clone()).multiplyScalar(0.5).toArray());
  setNums(BOX_R, [0, 0, 0]);
  if (!$('cut-name').value.trim()) $('cut-name').value = `${name}_cut`;
  syncCutTool();
  viewer.attachTool('cut');
}));

$('remove-box').addEventListener('click', () => viewer.showTool('cut', false));

$('cut').addEventListener('click', action(async () => {
  const name = requireSelected();
  if (!viewer.toolVisible('cut')) throw new LocalError('place a box first (Add box)');
  const box = readBox();
  const piece = $('cut-name').value.trim() || `${name}_cut`;
  await postSpec((spec) => {
    const p = findPart(spec, name);
    const cuts = p.cuts || [];
    spec.parts.push({
      name: piece,
      mesh: p.mesh,
      cuts: [...structuredClone(cuts), { op: 'intersect', box: structuredClone(box) }],
      boxes: [],
      collision: 'scan',
      fixed: false,
      mass: 0.5,
      friction: 0.8,
      rgba: [0, 0, 0, 0],
    });
    p.cuts = [...cuts, { op: 'subtract', box: structuredClone(box) }];
  }, `cut ${name} → ${name} + ${piece}`);
  viewer.showTool('cut', false);
  select(piece);
}));

// One cut on the selected part alone: "subtract" removes what is inside the box (a wall of the
// table caught in the part), "intersect" keeps only what is inside.
for (const op of ['subtract', 'intersect']) {
  $(`cut-${op}`).addEventListener('click', action(async () => {
    const name = requireSelected();
    if (!viewer.toolVisible('cut')) throw new LocalError('place a box first (Add box)');
    const box = readBox();
    await postSpec((spec) => {
      const p = findPart(spec, name);
      p.cuts = [...(p.cuts || []), { op, box: structuredClone(box) }];
    }, `${op === 'subtract' ? 'removed the box from' : 'kept the box of'} ${name}`);
    viewer.showTool('cut', false);
  }));
}

// ---- joint tool -----------------------------------------------------------------
function syncJointTool() {
  try {
    viewer.setJointTool({ origin: nums(J_ORIGIN), axis: nums(J_AXIS) });
  } catch {
    // half-typed
  }
}

function readJoint() {
  const name = $('joint-name').value.trim();
  if (!name) throw new LocalError('joint name: empty');
  const axis = nums(J_AXIS);
  const origin = nums(J_ORIGIN);
  return {
    name,
    type: $('joint-type').value,
    parent: $('joint-parent').value,
    child: $('joint-child').value,
    axis,
    origin,
    range: [num('joint-lower'), num('joint-upper')],
    damping: num('joint-damping'),
    frictionloss: num('joint-frictionloss'),
  };
}

function pickJoint(name) {
  const j = state.spec.joints.find((x) => x.name === name);
  if (!j) return;
  $('joint-name').value = j.name;
  $('joint-type').value = j.type;
  $('joint-parent').value = j.parent;
  $('joint-child').value = j.child;
  setExact(J_AXIS, j.axis || [0, 0, 1]);
  setExact(J_ORIGIN, j.origin || [0, 0, 0]);
  setExact(['joint-lower', 'joint-upper'], j.range || [0, 0]);
  setExact(['joint-damping', 'joint-frictionloss'], [j.damping ?? 0, j.frictionloss ?? 0]);
  setEditing('joint', name);
  state.touched.joint = true;
  syncJointTool();
  viewer.attachTool('joint');
}

function setEditing(kind, name) {
  state.editing[kind] = name;
  const b = $(`update-${kind}`);
  b.disabled = !name;
  b.textContent = name ? `Update '${name}'` : 'Update';
  for (const li of $(`${kind}s`).children) li.classList.toggle('selected', li.dataset[kind] === name);
}

$('joint-place').addEventListener('click', action(async () => {
  const name = requireSelected();
  setNums(J_ORIGIN, partCentre(name));
  $('joint-child').value = name;
  state.touched.joint = true;
  syncJointTool();
  viewer.attachTool('joint');
}));

$('add-joint').addEventListener('click', action(async () => {
  const j = readJoint();
  await postSpec((spec) => { spec.joints.push(j); }, `added joint ${j.name}`);
  afterToolAdd('joint');
}));

$('update-joint').addEventListener('click', action(async () => {
  const old = state.editing.joint;
  const j = readJoint();
  await postSpec((spec) => {
    const i = spec.joints.findIndex((x) => x.name === old);
    if (i < 0) throw new LocalError(`no joint named '${old}'`);
    spec.joints[i] = { ...spec.joints[i], ...j };
  }, `updated joint ${j.name}`);
  afterToolAdd('joint');
}));

// ---- site tool ------------------------------------------------------------------
function syncSiteTool() {
  try {
    viewer.setSiteTool({ position: nums(S_POS), yaw: num('site-yaw') });
  } catch {
    // half-typed
  }
}

function readSite() {
  const name = $('site-name').value.trim();
  if (!name) throw new LocalError('site name: empty');
  return { name, part: $('site-part').value, position: nums(S_POS), yaw: num('site-yaw') };
}

function pickSite(name) {
  const s = state.spec.sites.find((x) => x.name === name);
  if (!s) return;
  $('site-name').value = s.name;
  $('site-part').value = s.part;
  setExact([...S_POS, 'site-yaw'], [...(s.position || [0, 0, 0]), s.yaw ?? 0]);
  setEditing('site', name);
  state.touched.site = true;
  syncSiteTool();
  viewer.attachTool('site');
}

$('site-place').addEventListener('click', action(async () => {
  const name = requireSelected();
  setNums(S_POS, partCentre(name));
  $('site-part').value = name;
  state.touched.site = true;
  syncSiteTool();
  viewer.attachTool('site');
}));

$('add-site').addEventListener('click', action(async () => {
  const s = readSite();
  await postSpec((spec) => { spec.sites.push(s); }, `added site ${s.name}`);
  afterToolAdd('site');
}));

$('update-site').addEventListener('click', action(async () => {
  const old = state.editing.site;
  const s = readSite();
  await postSpec((spec) => {
    const i = spec.sites.findIndex((x) => x.name === old);
    if (i < 0) throw new LocalError(`no site named '${old}'`);
    spec.sites[i] = { ...spec.sites[i], ...s };
  }, `updated site ${s.name}`);
  afterToolAdd('site');
}));

// After an accepted add: the tool goes back to following the selection.
function afterToolAdd(kind) {
  state.touched[kind] = false;
  setEditing(kind, null);
  $(`${kind}-name`).value = '';
  viewer.showTool(kind, false);
}

// ---- fields <-> gizmo -------------------------------------------------------------
// Typing in a tool's fields moves its object; focusing them shows it and grabs it.
function bindFields(ids, kind, sync) {
  for (const id of ids) {
    const el = $(id);
    const onEdit = () => {
      if (kind !== 'cut') state.touched[kind] = true;
      sync();
    };
    el.addEventListener('input', onEdit);
    el.addEventListener('change', onEdit);
    el.addEventListener('focus', () => {
      if (kind === 'cut' && !viewer.toolVisible('cut')) return;
      if (kind !== 'cut') {
        sync();
        state.touched[kind] = true;
      }
      viewer.attachTool(kind);
    });
  }
}
bindFields([...BOX_C, ...BOX_S, ...BOX_R], 'cut', syncCutTool);
bindFields([...J_AXIS, ...J_ORIGIN], 'joint', syncJointTool);
bindFields([...S_POS, 'site-yaw', 'site-part'], 'site', syncSiteTool);

// Dragging the gizmo writes the fields.
function toolMoved(tool) {
  if (tool === 'cut') {
    const b = viewer.getCutBox();
    setNums(BOX_C, b.center);
    setNums(BOX_S, b.size);
    setNums(BOX_R, b.euler);
  } else if (tool === 'joint') {
    const j = viewer.getJointTool();
    setNums(J_ORIGIN, j.origin);
    setNums(J_AXIS, j.axis);
    state.touched.joint = true;
  } else if (tool === 'site') {
    const s = viewer.getSiteTool();
    setNums(S_POS, s.position);
    setNum('site-yaw', s.yaw);
    state.touched.site = true;
  }
}

// ---- gizmo mode, view toggles, keys --------------------------------------------------
function setMode(mode) {
  viewer.setMode(mode);
  for (const m of ['translate', 'scale', 'rotate']) $(`mode-${m}`).classList.toggle('active', m === mode);
}
for (const m of ['translate', 'scale', 'rotate']) $(`mode-${m}`).addEventListener('click', () => setMode(m));

for (const what of ['scan', 'parts', 'collision']) {
  $(`show-${what}`).addEventListener('change', (e) => viewer.setShow(what, e.target.checked));
}

const doUndo = action(async () => {
  const t = await api.undo();
  clearError();
  applyTwin(t);
  viewer.clearExport();
  await refreshParts();
  setStatus('ready · undone');
});
$('undo').addEventListener('click', doUndo);

window.addEventListener('keydown', (e) => {
  const typing = /^(INPUT|SELECT|TEXTAREA)$/.test(e.target.tagName);
  if ((e.ctrlKey || e.metaKey) && !e.shiftKey && e.key.toLowerCase() === 'z') {
    if (typing) return; // a field's own undo
    e.preventDefault();
    doUndo();
    return;
  }
  if (typing || e.ctrlKey || e.metaKey || e.altKey) return;
  const k = e.key.toLowerCase();
  if (k === 'w') setMode('translate');
  else if (k === 'e') setMode('scale');
  else if (k === 'r') setMode('rotate');
  else if (e.key === 'Escape') viewer.detachTool();
});

window.addEventListener('beforeunload', (e) => {
  if (state.twin?.dirty) e.preventDefault();
});

// ---- save and export -------------------------------------------------------------------
$('save').addEventListener('click', action(async () => {
  const r = await api.save();
  clearError();
  applyTwin(await api.twin()); // the dirty flag is now off
  setStatus(`Saved ${r.saved}`);
}));

$('export').addEventListener('click', action(async () => {
  const r = await api.exportScene();
  clearError();
  if (r.state?.spec) applyTwin(r.state);
  const geoms = r.geoms || [];
  const collision = geoms.filter((g) => g.collision).length;
  const parts = state.spec.parts.map((p) => p.name);
  viewer.showExport(r, (body) => (parts.includes(body) ? partColor(parts.indexOf(body)) : null));
  $('show-parts').checked = viewer.show.parts;
  $('show-collision').checked = viewer.show.collision;
  setStatus(`Exported ${collision} collision geoms (${geoms.length - collision} visual) to ${r.scene}`);
}));

// ---- start ---------------------------------------------------------------------------
serial(async () => {
  try {
    setStatus('loading twin…');
    applyTwin(await api.twin());
    setStatus('loading scan…');
    try {
      viewer.setScan(await api.scan());
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 404)) showError(`scan: ${e.message}`);
    }
    setStatus('loading part meshes…');
    await refreshParts();
    const box = viewer.partsBox();
    viewer.fitTo(box.isEmpty() ? viewer.scanBox() : box.expandByScalar(0.15));
    // tools start at the scene's centre
    const c = viewer.orbit.target.toArray();
    setNums(J_ORIGIN, c);
    setNums(S_POS, c);
    syncJointTool();
    syncSiteTool();
    setStatus(`ready · ${state.spec.parts.length} parts, ${state.spec.joints.length} joints, ${state.spec.sites.length} sites`);
  } catch (e) {
    showError(e.message);
    setStatus('failed to load the twin');
  }
});
