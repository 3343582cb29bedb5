#!/usr/bin/env node
// The emulated headset: plays a recorded hand through the handblocks page in headless Chromium,
// with IWER (Meta's Immersive Web Emulation Runtime) as the page's WebXR runtime.
//
// Usage:
//   node services/webxr/driver/headset.js --url URL --samples FILE.bin [--hand right|left|both]
//        [--screenshot OUT.png] [--spectator] [--timeout-s N] [--plain-iwer] [--verbose]
//
// Modules (playwright-core, iwer) come from NODE_PATH (scripts/webxr-tools.sh, run by tests/run,
// installs them into target/webxr-node); Chromium is the system's /usr/bin/chromium, or $HB_CHROMIUM.
//
// FILE.bin: u32 count (samples), then per sample one record per hand played (--hand right or
// left: one, for that hand; --hand both: two, the right then the left): f64 time_ms, u8 tracked
// (1/0), 3 bytes pad, then 25 joints x 7 f32 (px py pz qx qy qz qw) in WebXR's joint order,
// little-endian. Both records of a sample hold the same time_ms.
//
// One sample per XR frame: before the frame's callbacks run, each hand's 25 joint spaces are set
// to its record (tracked = 0: that hand's input is disconnected, so the page sees no such hand
// that frame), so both hands of a sample reach the page in the same XR frame; and the page's
// window.handblocks.frameTimeOverride returns the sample's time_ms.
// The joint poses reach the page bit for bit: IWER's own getJointPose goes through a 4x4 matrix
// and back (mat4.getRotation, then a re-normalisation in XRRigidTransform), which changes the
// orientation's last bits and sometimes its sign, so this driver hands the page the sample's own
// position and orientation for the joints it set (see exactJointPose below); --plain-iwer leaves
// IWER's path alone, to measure what it alone gives. The driver checks what the page actually
// sends (every "hands" message, against the sample of its frame) and reports it as `exactness`.
//
// --spectator: the page without IWER; waits for a drawn world, takes the screenshot, prints a
// summary. Otherwise: prints one JSON line {framesSent, worldsReceived, worldsDrawn, jsMs,
// roundTripMs, samples, exactness, held, ...} after the last sample's worlds have come back
// (held: how far behind the hand a grasped block was drawn, see app.js's "the held block").
// --timeout-s (default 120) bounds each wait: the page's load, the server's ready, the XR
// session's start, and any 30 s-or-longer stall in the playback (the playback itself may take
// longer in total: one sample per display frame, about 60 a second).
// Exit: 0 on success; 2 with a message on stderr on any error.
'use strict';

const fs = require('fs');
const os = require('os');
const path = require('path');

function fail(message) {
  process.stderr.write(`headset: ${message}\n`);
  process.exit(2);
}

// ---------------------------------------------------------------- arguments
function parseArgs(argv) {
  const a = { hand: 'right', timeoutS: 120, spectator: false, plainIwer: false, verbose: false };
  for (let i = 0; i < argv.length; i++) {
    const k = argv[i];
    const val = () => {
      if (i + 1 >= argv.length) fail(`${k} needs a value`);
      return argv[++i];
    };
    switch (k) {
      case '--url': a.url = val(); break;
      case '--samples': a.samples = val(); break;
      case '--hand': a.hand = val(); break;
      case '--screenshot': a.screenshot = val(); break;
      case '--spectator': a.spectator = true; break;
      case '--timeout-s': a.timeoutS = Number(val()); break;
      case '--plain-iwer': a.plainIwer = true; break;
      case '--verbose': a.verbose = true; break;
      case '-h': case '--help':
        process.stdout.write('usage: node services/webxr/driver/headset.js --url URL --samples FILE.bin [--hand right|left|both] ' +
          '[--screenshot OUT.png] [--spectator] [--timeout-s N] [--plain-iwer] [--verbose]\n');
        process.exit(0);
        break;
      default: fail(`unknown argument ${k} (see --help)`);
    }
  }
  if (!a.url) fail('--url is required');
  if (!a.spectator && !a.samples) fail('--samples is required (or --spectator)');
  if (!['right', 'left', 'both'].includes(a.hand)) fail(`--hand must be right, left or both, not ${a.hand}`);
  if (!(a.timeoutS > 0)) fail('--timeout-s must be a positive number');
  return a;
}
const args = parseArgs(process.argv.slice(2));
const timeoutMs = args.timeoutS * 1000;

// ---------------------------------------------------------------- modules and browser
function loadModules() {
  let playwright;
  try {
    playwright = require('playwright-core');
  } catch (e) {
    fail('the module playwright-core is missing: `tests/run` (scripts/webxr-tools.sh) installs it into ' +
      'target/webxr-node; run with NODE_PATH=target/webxr-node/node_modules');
  }
  let iwerBundle = null;
  if (!args.spectator) {
    const roots = [...(process.env.NODE_PATH || '').split(path.delimiter).filter(Boolean), ...module.paths];
    for (const root of roots) {
      for (const f of ['iwer/build/iwer.min.js', 'iwer/build/iwer.js']) {
        const p = path.join(root, f);
        if (fs.existsSync(p)) { iwerBundle = p; break; }
      }
      if (iwerBundle) break;
    }
    if (!iwerBundle) {
      fail('the module iwer (its browser bundle iwer/build/iwer.min.js) is missing: `tests/run` ' +
        '(scripts/webxr-tools.sh) installs it into target/webxr-node; run with NODE_PATH=target/webxr-node/node_modules');
    }
  }
  return { playwright, iwerBundle };
}

function findChromium() {
  const candidates = process.env.HB_CHROMIUM ? [process.env.HB_CHROMIUM] : ['/usr/bin/chromium', '/usr/bin/chromium-browser'];
  for (const c of candidates) {
    try { fs.accessSync(c, fs.constants.X_OK); return c; } catch (e) { /* next */ }
  }
  fail(`no Chromium at ${candidates.join(' or ')}: install it (Debian: apt-get install -y chromium; ` +
    'scripts/packages.sh lists it) or set HB_CHROMIUM to its path');
  return null;
}

// ---------------------------------------------------------------- samples
const RECORD_BYTES = 8 + 4 + 25 * 7 * 4;
// The hands played, in the order of a sample's records.
const PLAYED = args.hand === 'both' ? ['right', 'left'] : [args.hand];
function readSamples(file) {
  let buf;
  try { buf = fs.readFileSync(file); } catch (e) { fail(`cannot read samples ${file}: ${e.message}`); }
  if (buf.length < 4) fail(`samples ${file}: shorter than its count`);
  const count = buf.readUInt32LE(0);
  const sampleBytes = RECORD_BYTES * PLAYED.length;
  if (buf.length !== 4 + count * sampleBytes) {
    fail(`samples ${file}: ${buf.length} bytes, but a count of ${count} samples of ${PLAYED.length} ` +
      `hand(s) needs ${4 + count * sampleBytes}`);
  }
  if (count === 0) fail(`samples ${file}: no samples`);
  // samples with a hand tracked, and each hand's
  let tracked = 0;
  const trackedByHand = PLAYED.map(() => 0);
  for (let i = 0; i < count; i++) {
    let any = false;
    PLAYED.forEach((h, k) => {
      if (buf[4 + (i * PLAYED.length + k) * RECORD_BYTES + 8] === 1) { trackedByHand[k]++; any = true; }
    });
    if (any) tracked++;
  }
  return { buf, count, tracked, trackedByHand };
}

// ---------------------------------------------------------------- the page side (runs in the page)
// Installed by addInitScript after IWER's bundle: builds the emulated Quest 3 with hands, and the
// per-frame hook that applies one sample per XR frame.
function pageSetup(opts) {
  const IW = globalThis.IWER;
  const JOINTS = [
    'wrist', 'thumb-metacarpal', 'thumb-phalanx-proximal', 'thumb-phalanx-distal', 'thumb-tip',
    'index-finger-metacarpal', 'index-finger-phalanx-proximal', 'index-finger-phalanx-intermediate',
    'index-finger-phalanx-distal', 'index-finger-tip', 'middle-finger-metacarpal',
    'middle-finger-phalanx-proximal', 'middle-finger-phalanx-intermediate', 'middle-finger-phalanx-distal',
    'middle-finger-tip', 'ring-finger-metacarpal', 'ring-finger-phalanx-proximal',
    'ring-finger-phalanx-intermediate', 'ring-finger-phalanx-distal', 'ring-finger-tip',
    'pinky-finger-metacarpal', 'pinky-finger-phalanx-proximal', 'pinky-finger-phalanx-intermediate',
    'pinky-finger-phalanx-distal', 'pinky-finger-tip',
  ];
  const D = {
    error: null, playing: false, done: false, index: 0, count: 0, frames: 0,
    // currentTracked: the sample's hands (opts.hands' order) tracked; tracked: any of them
    current: -1, currentTime: null, currentTracked: opts.hands.map(() => false), tracked: false,
    check: { compared: 0, exactFrames: 0, framesWithDiff: 0, sentWhileUntracked: 0, wrongMask: 0,
      timeExact: 0, timeDiff: 0, maxPosDiff: 0, maxQuatDiff: 0, quatSignFlips: 0, floatsDiffering: 0,
      fallbacks: 0, afterEnd: 0 },
  };
  window.__hbDriver = D;
  // The page merges into what is already there (app.js keeps fields set before it runs).
  window.handblocks = Object.assign(window.handblocks || {}, {
    // A sample's own time while the trace plays; after it, the trace's clock goes on at the
    // page's pace (the hand, now untracked, still sends frames, and their time must go on
    // increasing where the trace's left off).
    frameTimeOverride: (xrTime) => {
      if (D.currentTime === null) return xrTime;
      if (!D.done) {
        D.lastXrTime = xrTime;
        return D.currentTime;
      }
      return D.currentTime + Math.max(0, xrTime - D.lastXrTime);
    },
  });
  try {
    const device = new IW.XRDevice(IW.metaQuest3);
    // Chromium has a navigator.xr of its own (with no device behind it): replace it
    device.installRuntime({ forceInstall: true });
    if (!(navigator.xr instanceof IW.XRSystem)) throw new Error('IWER did not install its navigator.xr');
    device.primaryInputMode = 'hand';
    // the emulated head at IWER's default 1.6 m, pitched down to look at a table's height
    const pitch = -opts.headPitchDeg * Math.PI / 360;
    device.quaternion.set(Math.sin(pitch), 0, 0, Math.cos(pitch));
    D.device = device;
    const P_DEVICE = IW.P_DEVICE, P_SPACE = IW.P_SPACE, P_JOINT_SPACE = IW.P_JOINT_SPACE;
    const P_RIGID = IW.P_RIGID_TRANSFORM;
    const RECORD = 712, PER_SAMPLE = RECORD * opts.hands.length;
    // Byte offset of record k (opts.hands' order) of sample i.
    const recordAt = (i, k) => 4 + i * PER_SAMPLE + k * RECORD;
    // gl-matrix's mat4.fromRotationTranslation, as IWER uses it.
    function fromRotationTranslation(out, q, v) {
      const x = q[0], y = q[1], z = q[2], w = q[3];
      const x2 = x + x, y2 = y + y, z2 = z + z;
      const xx = x * x2, xy = x * y2, xz = x * z2, yy = y * y2, yz = y * z2, zz = z * z2;
      const wx = w * x2, wy = w * y2, wz = w * z2;
      out[0] = 1 - (yy + zz); out[1] = xy + wz; out[2] = xz - wy; out[3] = 0;
      out[4] = xy - wz; out[5] = 1 - (xx + zz); out[6] = yz + wx; out[7] = 0;
      out[8] = xz + wy; out[9] = yz - wx; out[10] = 1 - (xx + yy); out[11] = 0;
      out[12] = v[0]; out[13] = v[1]; out[14] = v[2]; out[15] = 1;
    }
    // The hands played (each with its record in a sample) and those not: disconnected until
    // the playback starts; a hand not played never appears.
    const played = opts.hands.map((name, k) => {
      const hand = device.hands[name];
      hand.connected = false;
      const spaces = JOINTS.map((j) => hand.inputSource.hand.get(j));
      if (spaces.some((s) => !s)) throw new Error('IWER hand lacks a WebXR joint');
      const exact = spaces.map(() => ({ p: new Float32Array(3), q: new Float32Array(4), on: false }));
      spaces.forEach((s, i) => { s.__hbExact = exact[i]; });
      // The target ray space is the hand's root: identity, so a joint's global pose is its offset.
      hand.updateTargetRaySpace = function () {
        const m = this.inputSource.targetRaySpace[P_SPACE].offsetMatrix;
        m.fill(0); m[0] = m[5] = m[10] = m[15] = 1;
      };
      // The joints: IWER's own pose update first (it keeps its per-joint radii), then the
      // record's translation and rotation into each joint space's offset matrix (what
      // fillPoses and IWER's getJointPose read), and the exact values for exactJointPose.
      const protoUpdate = Object.getPrototypeOf(hand).updateHandPose;
      hand.updateHandPose = function () {
        protoUpdate.call(this);
        if (D.current < 0 || !D.currentTracked[k]) return;
        const base = (recordAt(D.current, k) + 12) / 4;
        const f = D.f32;
        for (let i = 0; i < 25; i++) {
          const o = base + i * 7;
          const e = exact[i];
          e.p[0] = f[o]; e.p[1] = f[o + 1]; e.p[2] = f[o + 2];
          e.q[0] = f[o + 3]; e.q[1] = f[o + 4]; e.q[2] = f[o + 5]; e.q[3] = f[o + 6];
          e.on = !opts.plainIwer;
          fromRotationTranslation(spaces[i][P_SPACE].offsetMatrix, e.q, e.p);
        }
      };
      return { name, hand, exact };
    });
    for (const name of ['right', 'left']) {
      if (!opts.hands.includes(name)) device.hands[name].connected = false;
    }

    // Every device frame, before the page's callbacks: the next sample, every hand of it.
    const priv = device[P_DEVICE];
    const origFrameStart = priv.onFrameStart;
    priv.onFrameStart = function (frame) {
      D.frames++;
      if (D.playing && !D.done) {
        if (D.index < D.count) {
          if (D.index === 0) D.startedAt = performance.now();
          D.current = D.index++;
          D.currentTime = D.dv.getFloat64(recordAt(D.current, 0), true);
          D.tracked = false;
          played.forEach((h, k) => {
            const on = D.dv.getUint8(recordAt(D.current, k) + 8) === 1;
            D.currentTracked[k] = on;
            D.tracked = D.tracked || on;
            h.hand.connected = on;
            h.exact.forEach((e) => { e.on = false; });
          });
        } else {
          D.done = true;
          D.doneAt = performance.now();
          D.current = -1;
          D.tracked = false;
          played.forEach((h, k) => { D.currentTracked[k] = false; h.hand.connected = false; });
        }
      }
      return origFrameStart.call(this, frame);
    };

    // The joint pose as the emulated device reports it: the sample's own position and
    // orientation (IWER's version decomposes the 4x4 matrix and re-normalises the quaternion).
    // Only for the joints this driver set, and only when both the joint's and the base space's
    // chains are identity above them (as they are here: local-floor is IWER's global space).
    const isIdentity = (m) => m[0] === 1 && m[5] === 1 && m[10] === 1 && m[15] === 1 &&
      m[1] === 0 && m[2] === 0 && m[3] === 0 && m[4] === 0 && m[6] === 0 && m[7] === 0 &&
      m[8] === 0 && m[9] === 0 && m[11] === 0 && m[12] === 0 && m[13] === 0 && m[14] === 0;
    const chainIdentity = (space) => {
      for (let s = space; s; s = s[P_SPACE].parentSpace) if (!isIdentity(s[P_SPACE].offsetMatrix)) return false;
      return true;
    };
    const origGetJointPose = IW.XRFrame.prototype.getJointPose;
    IW.XRFrame.prototype.getJointPose = function (joint, baseSpace) {
      const e = joint && joint.__hbExact;
      if (!e || !e.on) return origGetJointPose.call(this, joint, baseSpace);
      if (!chainIdentity(baseSpace) || !chainIdentity(joint[P_SPACE].parentSpace)) {
        D.check.fallbacks++;
        return origGetJointPose.call(this, joint, baseSpace);
      }
      const pose = origGetJointPose.call(this, joint, baseSpace);   // IWER's checks, radius
      const t = new IW.XRRigidTransform();
      const r = t[P_RIGID];
      r.position.set(e.p);
      r.orientation.set(e.q);
      r.positionPoint = new DOMPointReadOnly(e.p[0], e.p[1], e.p[2], 1);
      r.orientationPoint = new DOMPointReadOnly(e.q[0], e.q[1], e.q[2], e.q[3]);
      t.updateMatrix();
      return new IW.XRJointPose(t, joint[P_JOINT_SPACE].radius, pose.emulatedPosition);
    };

    // What the page sends: each hands message against the sample of its frame.
    const origSend = WebSocket.prototype.send;
    const f32bits = new Float32Array(1), u32bits = new Uint32Array(f32bits.buffer);
    const bitsOf = (x) => { f32bits[0] = x; return u32bits[0]; };
    WebSocket.prototype.send = function (data) {
      try {
        if (data instanceof ArrayBuffer && data.byteLength >= 24) checkHands(new DataView(data));
      } catch (err) { D.checkError = String(err); }
      return origSend.call(this, data);
    };
    // The page's mask bit of each hand (bit 0 left, bit 1 right); a message holds the left
    // hand's joints first.
    const BIT = { left: 1, right: 2 };
    function checkHands(dv) {
      if (dv.getUint32(0, true) !== 0x31584248 || dv.getUint8(4) !== 1) return;
      const c = D.check;
      if (!D.playing) return;
      if (D.done || D.current < 0) { c.afterEnd++; return; }
      if (!D.tracked) { c.sentWhileUntracked++; return; }
      const mask = dv.getUint8(5);
      let want = 0;
      played.forEach((h, k) => { if (D.currentTracked[k]) want |= BIT[h.name]; });
      const n = (want & 1) + (want >> 1);
      if (mask !== want || dv.byteLength !== 24 + 800 * n) { c.wrongMask++; return; }
      c.compared++;
      const t = dv.getFloat64(16, true);
      if (t === D.currentTime) c.timeExact++; else c.timeDiff++;
      let diff = 0;
      played.forEach((h, k) => {
        if (!D.currentTracked[k]) return;
        // where this hand's joints are in the message: after the left hand's, if present
        const at = 24 + (h.name === 'right' && (want & 1) ? 800 : 0);
        const base = recordAt(D.current, k) + 12;
        for (let i = 0; i < 25; i++) {
          let qDot = 0;
          for (let m = 0; m < 7; m++) {
            const want32 = D.dv.getUint32(base + (i * 7 + m) * 4, true);
            const gotF = dv.getFloat32(at + i * 32 + m * 4, true);
            const got32 = bitsOf(gotF);
            const wantF = D.dv.getFloat32(base + (i * 7 + m) * 4, true);
            if (m >= 3) qDot += gotF * wantF;
            if (want32 !== got32) {
              diff++;
              const d = Math.abs(gotF - wantF);
              if (m < 3) c.maxPosDiff = Math.max(c.maxPosDiff, d);
            }
          }
          if (qDot < 0) c.quatSignFlips++;
          // orientation difference up to sign
          let dq = 0, dqn = 0;
          for (let m = 3; m < 7; m++) {
            const g = dv.getFloat32(at + i * 32 + m * 4, true), w = D.dv.getFloat32(base + (i * 7 + m) * 4, true);
            dq = Math.max(dq, Math.abs(g - w)); dqn = Math.max(dqn, Math.abs(g + w));
          }
          c.maxQuatDiff = Math.max(c.maxQuatDiff, Math.min(dq, dqn));
        }
      });
      c.floatsDiffering += diff;
      if (diff === 0) c.exactFrames++; else c.framesWithDiff++;
    }
  } catch (err) {
    D.error = String(err && err.stack || err);
  }
  D.load = (b64) => {
    const bin = atob(b64);
    const bytes = new Uint8Array(new ArrayBuffer(bin.length));
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    D.dv = new DataView(bytes.buffer);
    D.count = D.dv.getUint32(0, true);
    // joints start at byte 4 + 712 r + 12 (record r): 4-aligned, so one Float32Array view
    // serves them all
    D.f32 = new Float32Array(bytes.buffer, 0, bytes.length >> 2);
    return D.count;
  };
}

// ---------------------------------------------------------------- helpers
function percentiles(list) {
  const a = list.filter((x) => Number.isFinite(x)).sort((x, y) => x - y);
  if (!a.length) return { n: 0, p50: null, p90: null, p99: null, max: null };
  const q = (p) => a[Math.min(a.length - 1, Math.floor(p * (a.length - 1) + 0.5))];
  const r = (x) => Math.round(x * 1000) / 1000;
  return { n: a.length, p50: r(q(0.5)), p90: r(q(0.9)), p99: r(q(0.99)), max: r(a[a.length - 1]) };
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function main() {
  const { playwright, iwerBundle } = loadModules();
  const executablePath = findChromium();
  const samples = args.spectator ? null : readSamples(args.samples);
  const userDataDir = fs.mkdtempSync(path.join(os.tmpdir(), 'hb-headset-'));
  let context = null;
  const cleanup = async () => {
    try { if (context) await context.close(); } catch (e) { /* closing anyway */ }
    try { fs.rmSync(userDataDir, { recursive: true, force: true }); } catch (e) { /* temp */ }
  };
  const pageErrors = [];
  try {
    try {
      context = await playwright.chromium.launchPersistentContext(userDataDir, {
        executablePath,
        headless: true,
        ignoreHTTPSErrors: true,
        viewport: { width: 1280, height: 720 },
        timeout: timeoutMs,
        args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
          '--disable-background-networking', '--disable-component-update', '--disable-sync',
          '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-certificate-errors'],
      });
    } catch (e) {
      throw new Error(`could not start Chromium (${executablePath}): ${e.message.split('\n')[0]}`);
    }
    const page = context.pages()[0] || await context.newPage();
    page.setDefaultTimeout(timeoutMs);
    page.on('pageerror', (e) => { pageErrors.push(String(e)); process.stderr.write(`headset: page error: ${e}\n`); });
    page.on('console', (m) => {
      if (args.verbose || m.type() === 'error') process.stderr.write(`headset: page console.${m.type()}: ${m.text()}\n`);
    });

    if (!args.spectator) {
      const bundle = fs.readFileSync(iwerBundle, 'utf8');
      await page.addInitScript({ content: bundle + '\n;(' + pageSetup.toString() + ')(' +
        JSON.stringify({ hands: PLAYED, plainIwer: args.plainIwer, headPitchDeg: 40 }) + ');\n' });
    }

    try {
      await page.goto(args.url, { waitUntil: 'load', timeout: timeoutMs });
    } catch (e) {
      throw new Error(`could not open ${args.url}: ${e.message.split('\n')[0]}`);
    }
    await page.waitForFunction(() => !!window.handblocks, null, { timeout: timeoutMs });

    if (args.spectator) {
      await waitFor(page, () => window.handblocks.worldsDrawn > 0 || /refused/.test(window.handblocks.status),
        'the first drawn world');
      const hb = await page.evaluate(() => ({ ...window.handblocks, stats: undefined, frameTimeOverride: undefined }));
      if (/refused/.test(hb.status)) throw new Error(`the server refused the page: ${hb.status}`);
      await sleep(300);
      if (args.screenshot) await page.screenshot({ path: args.screenshot });
      const out = await page.evaluate(() => {
        const h = window.handblocks;
        return { mode: 'spectator', status: h.status, blocks: h.blocks, worldsReceived: h.worldsReceived,
          worldsDrawn: h.worldsDrawn, lastWorldTime: h.lastWorldTime, xr: document.getElementById('xrline').textContent };
      });
      if (args.screenshot) out.screenshot = args.screenshot;
      process.stdout.write(JSON.stringify(out) + '\n');
      return 0;
    }

    const setupError = await page.evaluate(() => (window.__hbDriver ? window.__hbDriver.error : 'the driver\'s page setup did not run'));
    if (setupError) throw new Error(`IWER setup in the page failed: ${setupError}`);
    // the samples into the page, once
    const loaded = await page.evaluate((b64) => window.__hbDriver.load(b64), samples.buf.toString('base64'));
    if (loaded !== samples.count) throw new Error(`the page loaded ${loaded} samples of ${samples.count}`);

    await waitFor(page, () => !document.getElementById('enter-vr').hidden || /refused/.test(window.handblocks.status),
      'the Enter VR button');
    await page.click('#enter-vr');
    await waitFor(page, () => window.handblocks.xrMode === 'immersive-vr' || !!window.handblocks.message,
      'the immersive-vr session');
    const mode = await page.evaluate(() => window.handblocks.xrMode);
    if (mode !== 'immersive-vr') throw new Error(`no XR session: ${await page.evaluate(() => window.handblocks.message)}`);
    await waitFor(page, () => window.handblocks.ready === true || /refused/.test(window.handblocks.status),
      'the server\'s ready');
    const st = await page.evaluate(() => window.handblocks.status);
    if (/refused/.test(st)) throw new Error(`the server refused the page: ${st}`);

    // play: one sample per XR frame
    await page.evaluate(() => { window.__hbDriver.playing = true; });
    let last = -1, lastChange = Date.now(), shot = !args.screenshot;
    const stallMs = Math.max(30000, timeoutMs);
    for (;;) {
      const s = await page.evaluate(() => ({ i: window.__hbDriver.index, done: window.__hbDriver.done,
        status: window.handblocks.status, tracked: window.__hbDriver.tracked }));
      if (s.done) break;
      if (!shot && s.i >= samples.count / 2 && s.tracked) {
        // mid-playback, the hand in view (at the end it is gone)
        await page.screenshot({ path: args.screenshot });
        shot = true;
      }
      if (s.i !== last) { last = s.i; lastChange = Date.now(); }
      if (Date.now() - lastChange > stallMs) {
        throw new Error(`the playback stalled at sample ${s.i} of ${samples.count} (page status: ${s.status})`);
      }
      await sleep(200);
    }
    // the last frame's worlds: they come back within a frame or two; the page goes on sending
    // frames without a hand (and the session answering them) after the trace, so worlds do not
    // stop coming: 1.5 s is ample on a loaded machine.
    await sleep(1500);
    if (!shot) await page.screenshot({ path: args.screenshot });
    const r = await page.evaluate(() => {
      const h = window.handblocks, D = window.__hbDriver;
      return { framesSent: h.framesSent, framesSkipped: h.framesSkipped, worldsReceived: h.worldsReceived,
        worldsDrawn: h.worldsDrawn, jsMs: h.stats.jsMs, roundTripMs: h.stats.roundTripMs, check: D.check,
        held: { lagFrames: h.stats.heldLagFrames || [], distMm: h.stats.heldDistMm || [],
          worldLagFrames: h.stats.heldWorldLagFrames || [], worldDistMm: h.stats.heldWorldDistMm || [] },
        checkError: D.checkError || null, played: D.index,
        playMs: D.doneAt - D.startedAt, status: h.status, message: h.message };
    });
    const c = r.check;
    let exactness;
    const how = args.plainIwer ? 'IWER getJointPose unpatched' : 'getJointPose with the sample\'s own pose';
    if (r.checkError) {
      exactness = `unknown: the check failed (${r.checkError})`;
    } else if (c.compared === 0) {
      exactness = 'unknown: no hands message was compared';
    } else if (c.framesWithDiff === 0 && c.timeDiff === 0) {
      exactness = `bit-exact: ${c.compared}/${c.compared} hands frames carry the samples' 25x7 f32 and time_ms unchanged (${how})`;
    } else {
      exactness = `not exact: ${c.framesWithDiff}/${c.compared} frames differ in ${c.floatsDiffering} f32 ` +
        `(max |position diff| ${c.maxPosDiff.toExponential(2)} m, max |quaternion diff| up to sign ` +
        `${c.maxQuatDiff.toExponential(2)}, ${c.quatSignFlips} joint quaternions sign-flipped), ` +
        `${c.timeDiff} frame times differ (${how})`;
    }
    const out = {
      framesSent: r.framesSent, framesSkipped: r.framesSkipped, worldsReceived: r.worldsReceived,
      worldsDrawn: r.worldsDrawn, jsMs: percentiles(r.jsMs), roundTripMs: percentiles(r.roundTripMs),
      hand: args.hand, samples: samples.count, samplesTracked: samples.tracked,
      samplesTrackedByHand: Object.fromEntries(PLAYED.map((h, k) => [h, samples.trackedByHand[k]])),
      samplesPlayed: r.played,
      framesPerSecond: Math.round(r.played / (r.playMs / 1000) * 10) / 10, exactness,
      check: { compared: c.compared, exactFrames: c.exactFrames, sentWhileUntracked: c.sentWhileUntracked,
        wrongMask: c.wrongMask, fallbacks: c.fallbacks, afterEnd: c.afterEnd },
      // Per XR frame drawing a grasped block with the hand in view: the drawn block's distance
      // from where R5 puts it for the frame's hand (mm) and the frames its pose is late by;
      // world*: the same for the world's pose of it (what the page drew before issue 41).
      held: { lagFrames: percentiles(r.held.lagFrames), distMm: percentiles(r.held.distMm),
        worldLagFrames: percentiles(r.held.worldLagFrames), worldDistMm: percentiles(r.held.worldDistMm) },
      pageErrors: pageErrors.length,
    };
    if (args.screenshot) out.screenshot = args.screenshot;
    process.stdout.write(JSON.stringify(out) + '\n');
    return 0;
  } finally {
    await cleanup();
  }
}

async function waitFor(page, fn, what) {
  try {
    await page.waitForFunction(fn, null, { timeout: timeoutMs, polling: 100 });
  } catch (e) {
    const st = await page.evaluate(() => window.handblocks && window.handblocks.status).catch(() => '?');
    throw new Error(`timed out after ${args.timeoutS} s waiting for ${what} (page status: ${st})`);
  }
}

const hardStop = setTimeout(() => fail('no result in time (the browser hung?)'), timeoutMs * 3 + 600000);
hardStop.unref();
main().then((code) => process.exit(code)).catch((e) => fail(e && e.message ? e.message : String(e)));
