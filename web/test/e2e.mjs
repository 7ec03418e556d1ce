#!/usr/bin/env node
// End-to-end test of the twin editor: a real `twinforge gui` server on a copy
// of a twin, driven through the page in headless Chromium (Debian's).
//
//   node web/test/e2e.mjs --twinforge BIN --twin DIR --artifacts DIR
//
// Cuts the first part in two, adds a joint and a site, checks a refused edit,
// undo, save (twin.yaml + twin.yaml.bak) and export. Prints ALL-GOOD and exits
// 0, or prints the reason and exits 1. Screenshots go to ARTIFACTS.
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { parseArgs } from 'node:util';
import { chromium } from 'playwright-core';
import YAML from 'yaml';

const { values: opt } = parseArgs({
  options: {
    twinforge: { type: 'string' },
    twin: { type: 'string' },
    artifacts: { type: 'string', default: 'e2e-artifacts' },
  },
});
if (!opt.twinforge || !opt.twin) {
  console.error('usage: node web/test/e2e.mjs --twinforge BIN --twin DIR [--artifacts DIR]');
  process.exit(2);
}

const TOTAL_TIMEOUT_MS = 120_000;
const T0 = Date.now();
const log = (...a) => console.log(`e2e [${((Date.now() - T0) / 1000).toFixed(1)}s]:`, ...a);
class TestFailure extends Error {}
function check(cond, what) {
  if (!cond) throw new TestFailure(what);
}
const near = (a, b, tol = 1e-6) =>
  Array.isArray(a) && Array.isArray(b) && a.length === b.length && a.every((x, i) => Math.abs(x - b[i]) <= tol);
const sameBox = (a, b) => a && b && near(a.center, b.center) && near(a.size, b.size) && near(a.euler || [0, 0, 0], b.euler || [0, 0, 0]);
const r4 = (v) => Math.round(v * 1e4) / 1e4;

let server = null;
let serverOut = '';
let serverErr = '';
let browser = null;
let page = null;
let tmp = null;
const pageErrors = [];
const httpErrors = []; // every HTTP error the page got
fs.mkdirSync(opt.artifacts, { recursive: true });

// ---- the server ----------------------------------------------------------------
function startServer(twinDir) {
  return new Promise((resolve, reject) => {
    server = spawn(opt.twinforge, ['gui', '--twin', twinDir, '--port', '0'], { stdio: ['ignore', 'pipe', 'pipe'] });
    const timer = setTimeout(() => reject(new TestFailure(`the server printed no URL in 30 s; stdout: ${serverOut} stderr: ${serverErr.slice(-2000)}`)), 30_000);
    server.stdout.on('data', (d) => {
      serverOut += d;
      const m = serverOut.match(/gui: serving (http:\/\/[^\s/]+\/)/);
      if (m) {
        clearTimeout(timer);
        resolve(m[1]);
      }
    });
    server.stderr.on('data', (d) => { serverErr += d; });
    server.on('error', (e) => { clearTimeout(timer); reject(new TestFailure(`cannot start ${opt.twinforge}: ${e.message}`)); });
    server.on('exit', (code, sig) => {
      clearTimeout(timer);
      reject(new TestFailure(`the server exited (code ${code}, signal ${sig}); stderr: ${serverErr.slice(-2000)}`));
    });
  });
}

async function stopServer() {
  if (!server || server.exitCode !== null || server.signalCode !== null) return;
  const exited = new Promise((r) => server.once('exit', r));
  server.kill('SIGTERM');
  const t = setTimeout(() => server.kill('SIGKILL'), 5000);
  await exited;
  clearTimeout(t);
}

// ---- page helpers ----------------------------------------------------------------
// Open the collapsible section holding an element so it can be typed into.
async function reveal(sel) {
  await page.$eval(sel, (el) => { for (let d = el.closest('details'); d; d = d.parentElement?.closest('details')) d.open = true; });
}
async function fill(id, value) {
  await reveal(`#${id}`);
  await page.fill(`#${id}`, String(value));
}
async function choose(id, value) {
  await reveal(`#${id}`);
  await page.selectOption(`#${id}`, String(value));
}
async function click(sel) {
  await reveal(sel);
  await page.click(sel);
}
const idle = () => page.waitForFunction(() => document.body.dataset.busy === '0', null, { timeout: 30_000 });
const statusText = () => page.textContent('#status');
const errorText = () => page.$eval('#error', (el) => (el.hidden ? '' : el.textContent));
async function getJson(url, init) {
  const r = await fetch(url, init);
  const body = await r.json();
  check(r.ok, `${init?.method || 'GET'} ${url}: HTTP ${r.status} ${JSON.stringify(body)}`);
  return body;
}

async function main() {
  // Copy the twin: the given one is never modified.
  const original = path.resolve(opt.twin);
  const originalYaml = fs.readFileSync(path.join(original, 'twin.yaml'));
  const originalSpec = YAML.parse(originalYaml.toString());
  tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'twinforge-e2e-'));
  const twin = path.join(tmp, path.basename(original));
  fs.cpSync(original, twin, { recursive: true });
  fs.rmSync(path.join(twin, 'twin.yaml.bak'), { force: true });
  log('twin copied to', twin);

  const url = await startServer(twin);
  log('server at', url);

  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: ['--no-sandbox', '--disable-gpu', '--headless=new', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      '--enable-unsafe-swiftshader', '--use-angle=swiftshader'],
  });
  page = await browser.newPage({ viewport: { width: 1400, height: 900 } });
  page.on('pageerror', (e) => pageErrors.push(`page error: ${e.message}`));
  // Refused edits are expected HTTP errors; anything else the page logs as an error is a failure.
  page.on('console', (m) => {
    if (m.type() === 'error' && !/Failed to load resource/.test(m.text())) pageErrors.push(`console: ${m.text()}`);
  });
  page.on('response', (r) => {
    const u = new URL(r.url());
    if (r.status() >= 400 && u.pathname !== '/favicon.ico') httpErrors.push(`${r.request().method()} ${u.pathname}${u.search} -> ${r.status()}`);
  });
  await page.goto(url);
  await page.waitForFunction(() => /ready/.test(document.getElementById('status')?.textContent || ''), null, { timeout: 60_000 });
  await idle();
  log('page ready:', (await statusText()).trim());
  check(!(await errorText()), `error shown after loading: ${await errorText()}`);

  // ---- cut the first part in two -------------------------------------------------
  const first = await page.getAttribute('#parts [data-part]', 'data-part');
  check(originalSpec.parts.some((p) => p.name === first), `first list entry '${first}' is not a part of twin.yaml`);
  const partCount = await page.locator('#parts [data-part]').count();
  check(partCount === originalSpec.parts.length, `#parts has ${partCount} entries, twin.yaml ${originalSpec.parts.length} parts`);
  await click(`#parts [data-part="${first}"]`);
  const mesh = await getJson(`${url}api/part?name=${encodeURIComponent(first)}`);
  check(mesh.positions.length >= 9 && mesh.indices.length >= 3, `part '${first}' has no triangles`);
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < mesh.positions.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], mesh.positions[i + k]);
      hi[k] = Math.max(hi[k], mesh.positions[i + k]);
    }
  }
  // the half with larger x, a little past the mesh on the other sides
  const midX = (lo[0] + hi[0]) / 2;
  const box = {
    center: [r4((midX + hi[0] + 0.01) / 2), r4((lo[1] + hi[1]) / 2), r4((lo[2] + hi[2]) / 2)],
    size: [r4(hi[0] + 0.01 - midX), r4(hi[1] - lo[1] + 0.02), r4(hi[2] - lo[2] + 0.02)],
    euler: [0, 0, 0],
  };
  log(`cutting '${first}' with box`, JSON.stringify(box));
  await click('#add-box');
  await idle();
  const ids = ['cx', 'cy', 'cz', 'sx', 'sy', 'sz'];
  for (let i = 0; i < 3; i++) await fill(`box-${ids[i]}`, box.center[i]);
  for (let i = 0; i < 3; i++) await fill(`box-${ids[3 + i]}`, box.size[i]);
  await fill('box-yaw', 0);
  await fill('cut-name', 'piece');
  await click('#cut');
  await page.waitForSelector('#parts [data-part="piece"]', { timeout: 30_000 });
  await idle();
  check(!(await errorText()), `error after the cut: ${await errorText()}`);
  check(/unsaved changes/.test(await statusText()), `no dirty marker after an edit: '${await statusText()}'`);
  log('cut accepted:', (await statusText()).trim());

  // ---- trim another part: one subtract cut on it alone, no new part ----------------
  const other = originalSpec.parts.find((p) => p.name !== first)?.name;
  let trimBox = null;
  if (other) {
    await click(`#parts [data-part="${other}"]`);
    await click('#add-box');
    await idle();
    const value = async (id) => Number(await page.inputValue(`#${id}`));
    trimBox = {
      center: [await value('box-cx'), await value('box-cy'), await value('box-cz')],
      size: [await value('box-sx'), await value('box-sy'), await value('box-sz')],
    };
    const before = (await getJson(`${url}api/twin`)).spec.parts.length;
    await click('#cut-subtract');
    await idle();
    check(!(await errorText()), `error after trimming ${other}: ${await errorText()}`);
    const after = (await getJson(`${url}api/twin`)).spec;
    check(after.parts.length === before, `trimming ${other} changed the number of parts`);
    check(after.parts.find((p) => p.name === other).cuts.at(-1)?.op === 'subtract', `${other} has no subtract cut after the trim`);
    log(`trimmed '${other}' with box`, JSON.stringify(trimBox));
  }

  // a click on the new part in the 3D view selects it (raycast)
  await click(`#parts [data-part="${first}"]`);
  const spot = await page.evaluate(() => window.__twinforge.screenPointOf('piece'));
  if (spot) {
    await page.mouse.click(spot.x, spot.y);
    await page.waitForSelector('#parts [data-part="piece"].selected', { timeout: 5000 });
    check((await page.inputValue('#part-name')) === 'piece', 'clicking the part in the view did not fill the part panel');
    log('clicking the view selected piece');
  } else {
    log('piece not visible from the camera; view click not checked');
  }

  // ---- a prismatic joint ----------------------------------------------------------
  await fill('joint-name', 'slide');
  await choose('joint-type', 'prismatic');
  await choose('joint-parent', first);
  await choose('joint-child', 'piece');
  for (const [k, v] of [['x', 1], ['y', 0], ['z', 0]]) await fill(`joint-axis-${k}`, v);
  for (let i = 0; i < 3; i++) await fill(`joint-origin-${'xyz'[i]}`, box.center[i]);
  await fill('joint-lower', 0);
  await fill('joint-upper', 0.2);
  await fill('joint-damping', 10);
  await click('#add-joint');
  await page.waitForSelector('#joints [data-joint="slide"]', { timeout: 30_000 });
  await idle();
  check(!(await errorText()), `error after adding the joint: ${await errorText()}`);
  log('joint slide added');

  // ---- a site ----------------------------------------------------------------------
  const addSite = async (name) => {
    await fill('site-name', name);
    await choose('site-part', 'piece');
    for (let i = 0; i < 3; i++) await fill(`site-${'xyz'[i]}`, box.center[i]);
    await fill('site-yaw', 0);
    await click('#add-site');
    await idle();
  };
  await addSite('grip');
  await page.waitForSelector('#sites [data-site="grip"]', { timeout: 30_000 });
  check(!(await errorText()), `error after adding the site: ${await errorText()}`);
  log('site grip added');

  // ---- a refused edit: a second site named grip ------------------------------------------
  const before = (await getJson(`${url}api/twin`)).spec;
  await addSite('grip');
  await page.waitForFunction(() => !document.getElementById('error').hidden && /grip/.test(document.getElementById('error').textContent), null, { timeout: 30_000 });
  const err = await errorText();
  check(await page.isVisible('#error'), '#error is not visible');
  const color = await page.$eval('#error', (el) => getComputedStyle(el).color);
  log(`refused as expected: "${err.trim()}" (colour ${color})`);
  const after = (await getJson(`${url}api/twin`)).spec;
  check(JSON.stringify(before) === JSON.stringify(after), 'the refused edit changed the server\'s spec');
  check((await page.locator('#sites [data-site="grip"]').count()) === 1, 'the page lists grip twice after a refused edit');

  // ---- add a site and undo it ------------------------------------------------------------
  await addSite('tmp');
  await page.waitForSelector('#sites [data-site="tmp"]', { timeout: 30_000 });
  check(!(await errorText()), `the error was not cleared by the next accepted edit: ${await errorText()}`);
  await click('#undo');
  await page.waitForSelector('#sites [data-site="tmp"]', { state: 'detached', timeout: 30_000 });
  await idle();
  check(!(await getJson(`${url}api/twin`)).spec.sites.some((s) => s.name === 'tmp'), 'undo left site tmp on the server');
  check((await page.locator('#sites [data-site="grip"]').count()) === 1, 'undo removed more than site tmp');
  log('undo removed tmp');

  // ---- save and check twin.yaml ------------------------------------------------------------
  await click('#save');
  await page.waitForFunction(() => /Saved /.test(document.getElementById('status').textContent), null, { timeout: 30_000 });
  await idle();
  const saved = await statusText();
  log('status:', saved.trim());
  check(!/unsaved changes/.test(saved), 'the dirty marker is still on after saving');
  await click(`#parts [data-part="piece"]`);
  await page.screenshot({ path: path.join(opt.artifacts, 'gui.png') });

  const spec = YAML.parse(fs.readFileSync(path.join(twin, 'twin.yaml'), 'utf8'));
  const orig = spec.parts.find((p) => p.name === first);
  const piece = spec.parts.find((p) => p.name === 'piece');
  const origBefore = originalSpec.parts.find((p) => p.name === first);
  check(orig && piece, `twin.yaml lacks part '${first}' or 'piece'`);
  const nBefore = (origBefore.cuts || []).length;
  check(orig.cuts.length === nBefore + 1 && orig.cuts.at(-1).op === 'subtract' && sameBox(orig.cuts.at(-1).box, box),
    `${first}'s last cut is not subtract with the box: ${JSON.stringify(orig.cuts.at(-1))}`);
  check(piece.cuts.length === nBefore + 1 && piece.cuts.at(-1).op === 'intersect' && sameBox(piece.cuts.at(-1).box, box),
    `piece's last cut is not intersect with the box: ${JSON.stringify(piece.cuts.at(-1))}`);
  check(piece.mesh === origBefore.mesh, `piece's mesh ${piece.mesh} is not ${origBefore.mesh}`);
  check(piece.fixed === false && Math.abs(piece.mass - 0.5) < 1e-9, 'piece is not a movable 0.5 kg part');
  if (other) {
    const trimmed = spec.parts.find((p) => p.name === other);
    const n = (originalSpec.parts.find((p) => p.name === other).cuts || []).length;
    check(trimmed.cuts.length === n + 1 && trimmed.cuts.at(-1).op === 'subtract' &&
      near(trimmed.cuts.at(-1).box.center, trimBox.center, 1e-6) && near(trimmed.cuts.at(-1).box.size, trimBox.size, 1e-6),
      `${other}'s trim is not in twin.yaml: ${JSON.stringify(trimmed.cuts.at(-1))}`);
  }
  const slide = (spec.joints || []).find((j) => j.name === 'slide');
  check(slide && slide.type === 'prismatic' && slide.parent === first && slide.child === 'piece',
    `joint slide is wrong: ${JSON.stringify(slide)}`);
  check(near(slide.axis, [1, 0, 0], 1e-9) && near(slide.range, [0, 0.2], 1e-9), `joint slide axis/range: ${JSON.stringify(slide)}`);
  const grip = (spec.sites || []).filter((s) => s.name === 'grip');
  check(grip.length === 1 && grip[0].part === 'piece', `site grip is wrong: ${JSON.stringify(grip)}`);
  check(!(spec.sites || []).some((s) => s.name === 'tmp'), 'site tmp is in twin.yaml after undo');
  const bak = path.join(twin, 'twin.yaml.bak');
  check(fs.existsSync(bak), 'no twin.yaml.bak');
  check(fs.readFileSync(bak).equals(originalYaml), 'twin.yaml.bak differs from the original twin.yaml');
  log('twin.yaml and twin.yaml.bak are right');

  // ---- export ---------------------------------------------------------------------------
  const response = page.waitForResponse((r) => r.url().endsWith('/api/export'), { timeout: 60_000 });
  await click('#export');
  const exported = await (await response).json();
  await page.waitForFunction(() => /Exported/.test(document.getElementById('status').textContent), null, { timeout: 60_000 });
  await idle();
  check(!(await errorText()), `error after export: ${await errorText()}`);
  const geoms = exported.geoms || [];
  const collisions = geoms.filter((g) => g.collision);
  check(collisions.some((g) => g.body === 'piece'), `no collision geom on body 'piece' (bodies: ${[...new Set(collisions.map((g) => g.body))].join(', ')})`);
  check(geoms.some((g) => !g.collision && g.body === 'piece'), 'no visual geom on body piece');
  check(fs.existsSync(exported.scene), `exported scene ${exported.scene} does not exist`);
  const status = await statusText();
  check(status.includes(`${collisions.length} collision`), `status does not count ${collisions.length} collision geoms: '${status}'`);
  log('status:', status.trim());
  await page.screenshot({ path: path.join(opt.artifacts, 'gui_export.png') });

  // exactly one refused request: the second site grip
  check(httpErrors.length === 1 && httpErrors[0].startsWith('POST /api/spec -> 400'), `unexpected HTTP errors: ${httpErrors.join('; ')}`);
  check(pageErrors.length === 0, `errors in the page:\n${pageErrors.join('\n')}`);
}

// ---- run with a time limit, always clean up ----------------------------------------------
let failed = null;
const timer = setTimeout(() => { failed ??= `timed out after ${TOTAL_TIMEOUT_MS / 1000} s`; finish(); }, TOTAL_TIMEOUT_MS);
let finishing = false;
async function finish() {
  if (finishing) return;
  finishing = true;
  clearTimeout(timer);
  if (failed) {
    console.log(`e2e: FAILED: ${failed}`);
    if (pageErrors.length) console.log(pageErrors.join('\n'));
    if (httpErrors.length) console.log(`HTTP errors: ${httpErrors.join('; ')}`);
    if (serverErr) console.log(`server stderr (tail):\n${serverErr.slice(-3000)}`);
    if (page) {
      await Promise.race([
        page.screenshot({ path: path.join(opt.artifacts, 'gui_failure.png') }).catch(() => {}),
        new Promise((r) => setTimeout(r, 10_000)),
      ]);
    }
  }
  await Promise.race([browser?.close().catch(() => {}), new Promise((r) => setTimeout(r, 10_000))]);
  await stopServer().catch(() => {});
  if (!failed && tmp) fs.rmSync(tmp, { recursive: true, force: true });
  else if (tmp) console.log(`e2e: twin copy kept at ${tmp}`);
  if (!failed) console.log('ALL-GOOD');
  process.exit(failed ? 1 : 0);
}

main().then(
  () => finish(),
  (e) => {
    failed ??= e instanceof TestFailure ? e.message : (e.stack || String(e));
    finish();
  },
);
