// handblocks page: a spectator's orbit view of the stepper's world in any browser, and in a
// WebXR headset the same world in stereo with the hands drawn from their local joints; each XR
// frame's joints go to the server (the "hands" message), the server's worlds come back.
// Our own code: no third-party script, no build step, nothing fetched but gl.js (its matrices,
// meshes and orbit camera, from the same server) and the WebSocket.
'use strict';
import {
  M, programs, meshes, prism, sphere, boneMatrix, poseMul, poseInvMul, rotate, normalizeQuat,
  poseMatrix, poseDistanceMm, interpolatePose, orbitCamera, frameBox, orbitViewProj,
} from './gl.js';

(() => {
  // ---------------------------------------------------------------- test hook (merge, never clobber)
  const HB = (() => {
    const prior = (window.handblocks && typeof window.handblocks === 'object') ? window.handblocks : {};
    const defaults = {
      status: 'starting', ready: false, framesSent: 0, framesSkipped: 0, worldsReceived: 0,
      worldsDrawn: 0, lastWorldTime: null, blocks: [], stats: { jsMs: [], roundTripMs: [] },
      frameTimeOverride: null, xrMode: null, message: '',
      // true: draw a held block where the world put it, a round trip late (as before issue 41),
      // to compare by eye; the statistics below then measure that
      heldFromWorld: false,
    };
    const hb = Object.assign(defaults, prior);
    if (!hb.stats || typeof hb.stats !== 'object') hb.stats = {};
    // jsMs, roundTripMs: per frame; held*: per XR frame that draws a grasped block with the
    // driving hand in view (see "the held block" below)
    for (const k of ['jsMs', 'roundTripMs', 'heldLagFrames', 'heldDistMm', 'heldWorldLagFrames', 'heldWorldDistMm']) {
      if (!Array.isArray(hb.stats[k])) hb.stats[k] = [];
    }
    window.handblocks = hb;
    return hb;
  })();
  const STATS_KEEP = 10000;
  function keep(list, value) {
    list.push(value);
    if (list.length > STATS_KEEP + 1000) list.splice(0, list.length - STATS_KEEP);
  }

  // ---------------------------------------------------------------- constants
  const MAGIC = [0x48, 0x42, 0x58, 0x31]; // "HBX1"
  const KIND_HANDS = 1, KIND_STATS = 2, KIND_WORLD = 3, KIND_PONG = 4, KIND_PING = 5;
  const KIND_PEERS = 6;
  const JOINTS = [
    'wrist',
    'thumb-metacarpal', 'thumb-phalanx-proximal', 'thumb-phalanx-distal', 'thumb-tip',
    'index-finger-metacarpal', 'index-finger-phalanx-proximal', 'index-finger-phalanx-intermediate',
    'index-finger-phalanx-distal', 'index-finger-tip',
    'middle-finger-metacarpal', 'middle-finger-phalanx-proximal', 'middle-finger-phalanx-intermediate',
    'middle-finger-phalanx-distal', 'middle-finger-tip',
    'ring-finger-metacarpal', 'ring-finger-phalanx-proximal', 'ring-finger-phalanx-intermediate',
    'ring-finger-phalanx-distal', 'ring-finger-tip',
    'pinky-finger-metacarpal', 'pinky-finger-phalanx-proximal', 'pinky-finger-phalanx-intermediate',
    'pinky-finger-phalanx-distal', 'pinky-finger-tip',
  ];
  const JOINT_COUNT = 25, JOINT_FLOATS = 8, HAND_BYTES = JOINT_COUNT * JOINT_FLOATS * 4;
  // A hand as drawn: bones (prisms) along each finger from the wrist, a sphere at each joint,
  // and the palm, a fan of triangles from the wrist. WebXR's joints (XR hands) by index:
  // each finger from the wrist to its tip, and the palm's outline (wrist, the thumb's base
  // knuckle, the four knuckles).
  const XR_CHAINS = [[0, 1, 2, 3, 4], [0, 5, 6, 7, 8, 9], [0, 10, 11, 12, 13, 14],
    [0, 15, 16, 17, 18, 19], [0, 20, 21, 22, 23, 24]];
  const XR_PALM = [0, 2, 6, 11, 16, 21];
  // The same without the wrist, and without the metacarpals, for a runtime that leaves them
  // unset (an emulated headset playing a CARL trace, whose wrist and metacarpal joints are
  // the identity): the fingers from their metacarpals, the palm a fan from the middle one's
  // base; or from their knuckles, the palm across the knuckles and the thumb's.
  const XR_CHAINS_NO_WRIST = [[1, 2, 3, 4], [5, 6, 7, 8, 9], [10, 11, 12, 13, 14],
    [15, 16, 17, 18, 19], [20, 21, 22, 23, 24]];
  const XR_PALM_NO_WRIST = [10, 1, 2, 6, 11, 16, 21, 20];
  const XR_CHAINS_KNUCKLES = [[2, 3, 4], [6, 7, 8, 9], [11, 12, 13, 14], [16, 17, 18, 19],
    [21, 22, 23, 24]];
  const XR_PALM_KNUCKLES = [2, 6, 11, 16, 21];
  // A joint farther than this from the middle finger's knuckle (11) is not where the hand is
  // (metres): it is left out.
  const XR_HAND_REACH = 0.25;
  const PALM_MAX_CORNERS = 8;
  const PALM_FLOATS = (PALM_MAX_CORNERS - 2) * 3 * 6;
  // The world's fingers as the stepper drew them (a spectator's hand): radii, metres (the world
  // carries none; the hand model's are about these), and the colour of skin.
  const WORLD_BONE_R = 0.008, WORLD_JOINT_R = 0.0085;
  const SKIN = [0.90, 0.70, 0.56];
  // The headset's own hands (XR): as before, blue, the left a little lighter.
  const RIGHT_HAND = [0.35, 0.8, 0.95], LEFT_HAND = [0.55, 0.8, 0.95];

  // ---------------------------------------------------------------- DOM
  const $ = (id) => document.getElementById(id);
  const canvas = $('view');
  const statusEl = $('status'), worldLine = $('worldline'), xrLine = $('xrline');
  const legendEl = $('legend'), messageEl = $('message');
  const vrButton = $('enter-vr'), arButton = $('enter-ar');
  window.addEventListener('error', (e) => showMessage('page error: ' + e.message));

  function setStatus(text, cls) {
    HB.status = text;
    statusEl.textContent = text;
    statusEl.className = cls || '';
  }
  function showMessage(text) {
    HB.message = text;
    messageEl.textContent = text;
  }

  // ---------------------------------------------------------------- WebGL2
  const gl = canvas.getContext('webgl2', { antialias: true, xrCompatible: true, alpha: true });
  if (!gl) {
    showMessage('This browser has no WebGL2: the view cannot be drawn (the connection still works).');
  }

  const { lit: litProg, flat: flatProg } = gl ? programs(gl) : { lit: null, flat: null };

  const { makeMesh, freeMesh, makeDynamic, fillDynamic, makeLitDynamic } = meshes(gl);

  let floorMesh = null, gridLines = null, pointsBuf = null, fingerLines = null;
  let boneMesh = null, jointMesh = null, palmBuf = null;
  let gridFloorY = null;
  if (gl) {
    boneMesh = makeMesh(...prism(8));
    jointMesh = makeMesh(...sphere(12, 8));
    gridLines = makeDynamic();
    pointsBuf = makeDynamic();
    fingerLines = makeDynamic();
    palmBuf = makeLitDynamic(PALM_FLOATS);
  }
  function buildFloor(floorY) {
    if (!gl || gridFloorY === floorY) return;
    gridFloorY = floorY;
    const half = 2.0, step = 0.1, y = floorY;
    // short segments: a line that passes behind the eye is dropped whole by some rasterisers
    // (SwiftShader), so each line is cut at every grid step
    const lines = [], n = Math.round(2 * half / step), ly = y + 0.0005;
    for (let i = 0; i <= n; i++) {
      const c = -half + i * step;
      for (let k = 0; k < n; k++) {
        const a0 = -half + k * step, a1 = a0 + step;
        lines.push(c, ly, a0, c, ly, a1, a0, ly, c, a1, ly, c);
      }
    }
    fillDynamic(gridLines, new Float32Array(lines), lines.length / 3);
    freeMesh(floorMesh);
    floorMesh = makeMesh([-half, y, -half, half, y, -half, half, y, half, -half, y, half], [0, 2, 1, 0, 3, 2]);
  }

  // ---------------------------------------------------------------- scene and world state
  let scene = null;            // { floorY, stepHz, blocks: [{name, color, mesh}] }
  let world = null;            // newest world received
  let worldsThisSecond = 0, worldsPerSecond = null, worldRateStart = performance.now();

  // `msg`: the scene message as decodeScene reads it.
  function onScene(msg) {
    if (scene) for (const b of scene.blocks) freeMesh(b.mesh);
    const blocks = msg.blocks.map((b) => ({
      name: b.name,
      color: b.color,
      mesh: gl && b.vertices && b.indices ? makeMesh(b.vertices, b.indices) : null,
      // its hull's vertices (its own frame): R8's lift of a held block
      hull: Float64Array.from(b.vertices || []),
    }));
    const floorY = msg.floorY;
    scene = { session: msg.session, hand: msg.hand, floorY, stepHz: msg.stepHz, blocks };
    // The session moves the tracked hand by `offset` into the world (a standing user's hand,
    // ~1 m up, reaches blocks on the world's floor). In the headset the world is moved back by
    // as much, so that the blocks lie where the hand that moves them is: the world's floor at
    // table height, the hand where it really is.
    const off = msg.offset;
    worldToHeadsetPose.set([-off[0], -off[1], -off[2], 0, 0, 0, 1]);
    poseMatrix(worldToHeadset, worldToHeadsetPose, 0);
    // the hands[] index of each hand slot: hands[0] is the left, hands[1] the right
    slotHand = msg.hand === 'both' ? [1, 0] : msg.hand === 'left' ? [0] : [1];
    resetHeld(blocks.length);
    lastWristValid[0] = lastWristValid[1] = false;
    wristSeq.fill(0);
    originEstimated = false;
    HB.blocks = blocks.map((b) => b.name);
    HB.session = msg.session;
    buildFloor(floorY);
    legendEl.textContent = '';
    for (const b of blocks) {
      const item = document.createElement('span');
      item.className = 'item';
      const sw = document.createElement('span');
      sw.className = 'swatch';
      const c = b.color.map((v) => Math.round(Math.min(1, Math.max(0, v)) * 255));
      sw.style.background = `rgb(${c[0]},${c[1]},${c[2]})`;
      item.appendChild(sw);
      item.appendChild(document.createTextNode(b.name));
      legendEl.appendChild(item);
    }
    orbit.autoTarget = true;
  }

  function parseWorld(dv, buf) {
    const pageSeq = dv.getUint32(8, true);
    const count = dv.getUint32(12, true);
    const time = dv.getFloat64(16, true);
    const grasped = dv.getInt32(24, true);
    const points = dv.getUint32(28, true);
    const need = 32 + 32 * count + 12 * points;
    if (buf.byteLength < need) throw new Error(`world message of ${buf.byteLength} bytes, expected ${need}`);
    // per block 7 f32 (pose), u16 mode, u16 the hands that hold it (held_by); kept here as 8
    // numbers per block (the pose, the mode) and the holders apart
    const blocks = new Float32Array(count * 8), heldBy = new Uint8Array(count);
    for (let i = 0; i < count; i++) {
      const at = 32 + 32 * i;
      for (let k = 0; k < 7; k++) blocks[i * 8 + k] = dv.getFloat32(at + 4 * k, true);
      blocks[i * 8 + 7] = dv.getUint16(at + 28, true);
      heldBy[i] = dv.getUint16(at + 30, true) & 3;
    }
    const fingers = new Float32Array(points * 3);
    const base = 32 + 32 * count;
    for (let i = 0; i < points * 3; i++) fingers[i] = dv.getFloat32(base + 4 * i, true);
    return { pageSeq, count, time, grasped, points, blocks, heldBy, fingers, drawn: false };
  }

  // ---------------------------------------------------------------- round trip bookkeeping
  const RING = 256;
  const ringSeq = new Uint32Array(RING), ringTime = new Float64Array(RING);
  let pendingRoundTrip = -1;   // newest round trip measured since the last stats message

  function noteWorldDrawn(now) {
    if (!world || world.drawn) return;
    world.drawn = true;
    HB.worldsDrawn++;
    const s = world.pageSeq;
    if (s !== 0xFFFFFFFF && s !== 0 && ringSeq[s % RING] === s) {
      const rt = now - ringTime[s % RING];
      pendingRoundTrip = rt;
      keep(HB.stats.roundTripMs, rt);
      ringSeq[s % RING] = 0;   // measure each seq once
    }
  }

  // ---------------------------------------------------------------- the held blocks (R5)
  // A world answers the page's frame a round trip late, so a block drawn where the world put
  // it trails the hands drawn from this frame's joints. A grasped block moves rigidly with the
  // wrist of the hand that holds it (docs/model.md R5): block = W * offset, offset constant
  // while grasped. Each world says which hands hold each block (BlockState.held_by: bit 0 the
  // session's slot 0, the right hand or a one-hand session's only hand; bit 1 the left). So
  // the page takes, for each held block and each hand that holds it, the offset from that world
  // (offset = W_S^-1 * block_S, with W_S that hand's wrist of the frame S the world answers, as
  // the page sent it) and draws the block at W_now * offset: where the world will put it once
  // it has this frame. A block both hands hold moves by the mean of the two wrists' motions
  // (docs/model.md "Two hands"): it is drawn halfway between where each hand would put it
  // (the middle of the positions, the rotation halfway). All of it in the headset's frame
  // (local-floor): the world's poses through worldToHeadset.
  //
  // Poses here are 7 numbers: position x y z, then the unit quaternion x y z w.
  const WRIST_RING = 256;
  const wristSeq = new Uint32Array(WRIST_RING);          // the seq a slot holds (0: none)
  const wristTime = new Float64Array(WRIST_RING);        // the frame time it sent (ms)
  // Per hand (hands[] index, 0 left, 1 right): whether the ring slot holds that hand's wrist
  // (sent, or held from before while the hand was not in view: the session holds it too), the
  // wrist, and the wrist last seen.
  const wristKnown = [new Uint8Array(WRIST_RING), new Uint8Array(WRIST_RING)];
  const wristPose = [new Float64Array(WRIST_RING * 7), new Float64Array(WRIST_RING * 7)];
  const lastWrist = [new Float64Array(7), new Float64Array(7)];
  const lastWristValid = [false, false];
  // The hands[] index of each of the session's hand slots (the scene's `hand`): one hand in
  // slot 0, or the right in slot 0 and the left in slot 1.
  let slotHand = [1];
  // The page's time (as sent) of world time 0: each world answering frame S is the world at
  // the last step at or before S's time, so frameTime_S - 1000 * worldTime lies within one step
  // above it; the least seen is taken (and taken again if the mapping moves: a new driver).
  let originEstimated = false, originMs = 0;
  const worldToHeadsetPose = new Float64Array([0, 0, 0, 0, 0, 0, 1]);
  // Per block (sized by the scene): what the newest world says of it and what is drawn.
  const held = {
    world: null,            // the world this state was taken from
    n: 0,                   // blocks
    mask: new Uint8Array(0),      // the slots that hold it (held_by), 0: not held
    valid: new Uint8Array(0),     // the slots whose offset is known (from the newest world's frame)
    offset: new Float64Array(0),  // per block, per slot (2): the block in that wrist's frame
    graspValid: new Uint8Array(0),
    // The reference of a block one hand holds: the offset of the grasp's first world, carried
    // on by R5 and R8 (a lift out of the floor stays in it) frame by frame from this page's
    // own hand.
    refOffset: new Float64Array(0),
    list: [],               // the blocks held (mask != 0), lowest first
    draw: new Uint8Array(0),      // this frame draws block i at drawPose[7 i]
    drawPose: new Float64Array(0),
  };
  const tmpA = new Float64Array(7), tmpB = new Float64Array(7), tmpC = new Float64Array(7);
  const tmpD = new Float64Array(7), heldRefPose = new Float64Array(7);
  const heldWorldPose = new Float64Array(7);
  const heldModel = M.create();
  let heldDraw = false;      // this frame draws some held block from the hands

  function resetHeld(blocks) {
    if (blocks !== undefined && blocks !== held.n) {
      held.n = blocks;
      held.mask = new Uint8Array(blocks);
      held.valid = new Uint8Array(blocks);
      held.offset = new Float64Array(blocks * 14);
      held.graspValid = new Uint8Array(blocks);
      held.refOffset = new Float64Array(blocks * 7);
      held.draw = new Uint8Array(blocks);
      held.drawPose = new Float64Array(blocks * 7);
    }
    held.world = null;
    held.mask.fill(0); held.valid.fill(0); held.graspValid.fill(0); held.draw.fill(0);
    held.list.length = 0;
    heldDraw = false;
  }

  // A sent frame's wrists (a hand the frame lacks: its last one, as the session holds it).
  function noteWristSent(seq, frameTime, mask) {
    const slot = seq % WRIST_RING;
    wristSeq[slot] = seq;
    wristTime[slot] = frameTime;
    for (const h of slotHand) {
      const last = lastWrist[h];
      if (mask & (1 << h)) {
        const j = hands[h].joints;
        for (let k = 0; k < 7; k++) last[k] = j[k];
        normalizeQuat(last, 0);
        lastWristValid[h] = true;
      }
      wristKnown[h][slot] = lastWristValid[h] ? 1 : 0;
      if (lastWristValid[h]) wristPose[h].set(last, slot * 7);
    }
  }

  // Each world that answers a frame of this page's: the page's time of world time 0.
  function noteWorldTime(w) {
    const seq = w.pageSeq, slot = seq % WRIST_RING;
    if (seq === 0 || seq === 0xFFFFFFFF || wristSeq[slot] !== seq) return;
    const stepMs = scene && scene.stepHz > 0 ? 1000 / scene.stepHz : 1000 / 120;
    const v = wristTime[slot] - 1000 * w.time;
    if (!originEstimated || v < originMs || v > originMs + stepMs + 1e-3) {
      originMs = v;
      originEstimated = true;
    }
  }

  // Hand h's wrist at world time `worldTime` (s) of the world answering frame `seq`, as the
  // session's timeline has it (interpolated between the frames around that time: position
  // linearly, orientation by slerp); false if the frames it needs are no longer known.
  function wristAtWorld(h, seq, worldTime, out) {
    const slot = seq % WRIST_RING, known = wristKnown[h], poses = wristPose[h];
    if (!originEstimated || seq === 0 || seq === 0xFFFFFFFF || wristSeq[slot] !== seq || !known[slot]) return false;
    const t = originMs + 1000 * worldTime;
    const eps = 1e-4;   // ms: the session rounds frame times to whole ns
    if (t >= wristTime[slot] - eps) {
      for (let k = 0; k < 7; k++) out[k] = poses[slot * 7 + k];
      return true;
    }
    // the frame before t, and the one after it
    for (let back = 1; back < 16; back++) {
      const s0 = seq - back, a = s0 % WRIST_RING, b = (s0 + 1) % WRIST_RING;
      if (s0 <= 0 || wristSeq[a] !== s0 || !known[a]) return false;
      if (wristTime[a] > t + eps) continue;
      const span = wristTime[b] - wristTime[a];
      const f = span > 0 ? Math.min(1, Math.max(0, (t - wristTime[a]) / span)) : 1;
      interpolatePose(out, poses, a * 7, poses, b * 7, f);
      return true;
    }
    return false;
  }

  // Block i of world w in the headset's frame.
  function worldBlockPose(out, w, i) {
    const o = i * 8, b = w.blocks;
    tmpC[0] = b[o]; tmpC[1] = b[o + 1]; tmpC[2] = b[o + 2];
    tmpC[3] = b[o + 3]; tmpC[4] = b[o + 4]; tmpC[5] = b[o + 5]; tmpC[6] = b[o + 6];
    normalizeQuat(tmpC, 0);
    poseMul(out, 0, worldToHeadsetPose, 0, tmpC, 0);
  }

  // A new world: the grasps it states, and each held block's offset from the wrist of each
  // hand that holds it, at the frame it answers.
  function updateHeld() {
    if (held.world === world) return;
    held.world = world;
    held.list.length = 0;
    const n = world && scene ? Math.min(world.count, scene.blocks.length, held.n) : 0;
    for (let i = 0; i < held.n; i++) {
      // held_by's slots this session has (a one-hand session: slot 0 alone)
      const mask = i < n ? world.heldBy[i] & ((1 << slotHand.length) - 1) : 0;
      if (mask !== held.mask[i]) {
        held.mask[i] = mask; held.valid[i] = 0; held.graspValid[i] = 0;
      }
      if (!mask) continue;
      held.list.push(i);
      // No wrist for the frame it answers (a world of no frame of this page's): keep the
      // offsets the grasp had, if any.
      worldBlockPose(tmpB, world, i);
      for (let s = 0; s < slotHand.length; s++) {
        if (!(mask & (1 << s)) || !wristAtWorld(slotHand[s], world.pageSeq, world.time, tmpA)) continue;
        const o = (i * 2 + s) * 7;
        poseInvMul(held.offset, o, tmpA, 0, tmpB, 0);
        normalizeQuat(held.offset, o);
        held.valid[i] |= 1 << s;
      }
      if (held.valid[i] === mask && !held.graspValid[i]) {
        // the reference of a one-hand grasp (a two-hand grasp's is not measured)
        const s = mask === 1 ? 0 : mask === 2 ? 1 : -1;
        if (s >= 0) held.refOffset.set(held.offset.subarray((i * 2 + s) * 7, (i * 2 + s + 1) * 7), i * 7);
        held.graspValid[i] = 1;
      }
    }
  }

  // out = block i at hand h's last wrist and `offset[oo..]`, in the headset's frame: R5.
  function atHand(out, h, offset, oo) {
    poseMul(out, 0, lastWrist[h], 0, offset, oo);
  }

  // out = pose (block i in the headset's frame) with R8's lift, which a grasped block obeys
  // too (lifted out of the floor by the depth its lowest vertex is below it). out may be pose.
  function lifted(out, i, pose) {
    poseInvMul(tmpB, 0, worldToHeadsetPose, 0, pose, 0);   // in the world's frame
    const hull = scene.blocks[i].hull;
    let low = Infinity;
    for (let v = 0; v + 2 < hull.length; v += 3) {
      rotate(tmpC, 0, tmpB[3], tmpB[4], tmpB[5], tmpB[6], hull[v], hull[v + 1], hull[v + 2]);
      if (tmpC[1] < low) low = tmpC[1];
    }
    const depth = scene.floorY - (tmpB[1] + low);
    if (depth > 0) tmpB[1] += depth;
    poseMul(out, 0, worldToHeadsetPose, 0, tmpB, 0);
  }

  // out = held block i where its holders' hands (their last wrists) put it: one hand's R5, or
  // halfway between two hands' (the middle of the positions, the rotation halfway), lifted.
  function fromHands(out, i) {
    const mask = held.mask[i];
    let first = true;
    for (let s = 0; s < slotHand.length; s++) {
      if (!(mask & (1 << s))) continue;
      atHand(first ? out : tmpD, slotHand[s], held.offset, (i * 2 + s) * 7);
      if (!first) {
        for (let k = 0; k < 3; k++) out[k] = (out[k] + tmpD[k]) / 2;
        const sign = out[3] * tmpD[3] + out[4] * tmpD[4] + out[5] * tmpD[5] + out[6] * tmpD[6] < 0 ? -1 : 1;
        for (let k = 3; k < 7; k++) out[k] += sign * tmpD[k];
        normalizeQuat(out, 0);
      }
      first = false;
    }
    lifted(out, i, out);
  }

  // Once per XR frame, before drawing: where each held block is drawn, and (for a block one
  // hand holds, with that hand in view and this frame sent as `seq`) how far the drawn block
  // is from where R5 puts it for this frame's hand (held.refOffset: the grasp's first world's
  // offset, carried on by R5 and R8 from this page's frames, never from a later world), and
  // how many frames old the drawn pose is (0: this frame's hand); the same for the world's
  // pose of the block (what the page drew before issue 41: a round trip late).
  function prepareHeld(seq) {
    updateHeld();
    heldDraw = false;
    for (const i of held.list) {
      held.draw[i] = 0;
      const mask = held.mask[i];
      if (!world || held.valid[i] !== mask) continue;
      let inView = true, known = true;
      for (let s = 0; s < slotHand.length; s++) {
        if (!(mask & (1 << s))) continue;
        known = known && lastWristValid[slotHand[s]];
        inView = inView && hands[slotHand[s]].present;
      }
      if (!known) continue;
      const pose = held.drawPose.subarray(i * 7, i * 7 + 7);
      fromHands(pose, i);
      held.draw[i] = HB.heldFromWorld ? 0 : 1;
      heldDraw = heldDraw || held.draw[i] === 1;
      if (!seq || !inView || !held.graspValid[i] || (mask !== 1 && mask !== 2)) continue;
      if (world.pageSeq === 0 || world.pageSeq > seq) continue;   // a world of no frame of this page's
      const h = slotHand[mask === 1 ? 0 : 1];
      atHand(heldRefPose, h, held.refOffset, i * 7);
      lifted(heldRefPose, i, heldRefPose);
      poseInvMul(held.refOffset, i * 7, lastWrist[h], 0, heldRefPose, 0);
      worldBlockPose(heldWorldPose, world, i);
      const worldLag = seq - world.pageSeq;
      const worldDist = poseDistanceMm(heldWorldPose, 0, heldRefPose, 0);
      keep(HB.stats.heldWorldLagFrames, worldLag);
      keep(HB.stats.heldWorldDistMm, worldDist);
      keep(HB.stats.heldLagFrames, held.draw[i] ? 0 : worldLag);
      keep(HB.stats.heldDistMm, held.draw[i] ? poseDistanceMm(pose, 0, heldRefPose, 0) : worldDist);
    }
  }

  // ---------------------------------------------------------------- the page's protocol
  // Declared in Rust (common/webxr-wire: its lib.rs for the hands frame, page.rs for the rest);
  // tests/webxr_browser.rs passes every message through these, as HB.wire, and checks what
  // they read and write against the declaration.

  function header(buf, kind) {
    const u8 = new Uint8Array(buf);
    u8[0] = MAGIC[0]; u8[1] = MAGIC[1]; u8[2] = MAGIC[2]; u8[3] = MAGIC[3]; u8[4] = kind;
    return new DataView(buf);
  }

  // The scene message (page::Scene) as the page uses it: each field checked, with a default
  // where one is missing or not of its type; a block's vertices and indices null when absent.
  function decodeScene(msg) {
    const numbers = (v) => (Array.isArray(v) ? v.map(Number) : null);
    return {
      session: msg.session, hand: msg.hand, stepHz: msg.step_hz,
      floorY: Number.isFinite(msg.floor_y) ? msg.floor_y : 0,
      offset: Array.isArray(msg.offset) && msg.offset.length === 3 ? msg.offset.map(Number) : [0, 0, 0],
      blocks: (msg.blocks || []).map((b) => ({
        name: String(b.name),
        color: Array.isArray(b.color) && b.color.length >= 3 ? b.color.slice(0, 3).map(Number) : [0.7, 0.7, 0.7],
        vertices: numbers(b.vertices),
        indices: numbers(b.indices),
      })),
    };
  }

  // A text message (page::Text): { op: 'scene', scene } or { op: 'ready', offsetMs,
  // roundTripMs }; null for an op this page does not know; throws when it is no JSON.
  function decodeText(data) {
    const msg = JSON.parse(data);
    if (msg.op === 'scene') return { op: 'scene', scene: decodeScene(msg) };
    if (msg.op === 'ready') return { op: 'ready', offsetMs: msg.offset_ms, roundTripMs: msg.round_trip_ms };
    return null;
  }

  // The answer to a ping (kind 5, `data`) received at `arrived` (the page's clock, ms): kind 4,
  // the ping's seq and the server's time as received, bytes unchanged; null when no ping.
  function encodePong(data, arrived) {
    if (data.byteLength < 24) return null;
    const buf = new ArrayBuffer(32);
    const out = header(buf, KIND_PONG);
    out.setUint32(8, new DataView(data).getUint32(8, true), true);
    new Uint8Array(buf, 16, 8).set(new Uint8Array(data, 16, 8)); // the server's time, bytes as received
    out.setFloat64(24, arrived, true);
    return buf;
  }

  // A hands frame (kind 1): `joints[h]` the 25 x 8 floats of hand h (0 the left, 1 the right),
  // those of `mask`'s hands written, the left first.
  function encodeHands(seq, frameTime, mask, joints) {
    const n = (mask & 1 ? 1 : 0) + (mask & 2 ? 1 : 0);
    const buf = new ArrayBuffer(24 + HAND_BYTES * n);
    const dv = header(buf, KIND_HANDS);
    dv.setUint8(5, mask);
    dv.setUint32(8, seq, true);
    dv.setFloat64(16, frameTime, true);
    let off = 24;
    for (let h = 0; h < 2; h++) {
      if (!(mask & (1 << h))) continue;
      const j = joints[h];
      for (let i = 0; i < JOINT_COUNT * JOINT_FLOATS; i++, off += 4) dv.setFloat32(off, j[i], true);
    }
    return buf;
  }

  // A frame's statistics (kind 2); roundTripMs -1: none measured since the last.
  function encodeStats(seq, jsMs, roundTripMs) {
    const buf = new ArrayBuffer(32);
    const dv = header(buf, KIND_STATS);
    dv.setUint32(8, seq, true);
    dv.setFloat64(16, jsMs, true);
    dv.setFloat64(24, roundTripMs, true);
    return buf;
  }

  // Not enumerable: a copy of the hook's state ({ ...window.handblocks }) leaves it out.
  Object.defineProperty(HB, 'wire', {
    value: {
      text: decodeText, world: (buf) => parseWorld(new DataView(buf), buf),
      peers: (buf) => parsePeers(new DataView(buf), buf),
      // a message as if from the server's socket (tests feed the page through it)
      receive: (data) => onMessage(data),
      pong: encodePong, hands: encodeHands, stats: encodeStats,
    },
  });

  // ---------------------------------------------------------------- WebSocket
  const params = new URLSearchParams(location.search);
  const token = params.get('token') || '';
  let ws = null, refused = false;

  function connect() {
    if (refused) return;
    const scheme = location.protocol === 'https:' ? 'wss://' : 'ws://';
    const url = scheme + location.host + '/ws?token=' + encodeURIComponent(token);
    setStatus('connecting', 'connecting');
    let sock;
    try {
      sock = new WebSocket(url);
    } catch (e) {
      setStatus('disconnected (' + e.message + '), reconnecting', 'disconnected');
      setTimeout(connect, 1000);
      return;
    }
    sock.binaryType = 'arraybuffer';
    ws = sock;
    sock.onopen = () => { if (ws === sock) setStatus('connected, waiting for the server', 'connected'); };
    sock.onmessage = (ev) => { if (ws === sock) onMessage(ev.data); };
    sock.onclose = (ev) => {
      if (ws !== sock) return;
      ws = null;
      HB.ready = false;
      if (ev.code === 4001) {
        refused = true;
        setStatus('refused: ' + (ev.reason || 'wrong token') + ' (open the URL the server printed)', 'refused');
        return;
      }
      setStatus(`disconnected (code ${ev.code}${ev.reason ? ', ' + ev.reason : ''}), reconnecting every 1 s`, 'disconnected');
      setTimeout(connect, 1000);
    };
    sock.onerror = () => { /* onclose follows */ };
  }

  function send(buf) {
    if (ws && ws.readyState === WebSocket.OPEN) { ws.send(buf); return true; }
    return false;
  }

  function onMessage(data) {
    if (typeof data === 'string') {
      let msg;
      try { msg = decodeText(data); } catch (e) { showMessage('bad text message from the server'); return; }
      if (msg && msg.op === 'scene') {
        onScene(msg.scene);
        setStatus('connected, estimating the clock offset', 'connected');
      } else if (msg && msg.op === 'ready') {
        HB.ready = true;
        HB.offsetMs = msg.offsetMs;
        setStatus('connected, ready', 'connected');
      }
      return;
    }
    if (!(data instanceof ArrayBuffer) || data.byteLength < 8) return;
    const dv = new DataView(data);
    if (dv.getUint8(0) !== MAGIC[0] || dv.getUint8(1) !== MAGIC[1] || dv.getUint8(2) !== MAGIC[2] || dv.getUint8(3) !== MAGIC[3]) return;
    const kind = dv.getUint8(4);
    if (kind === KIND_PING && data.byteLength >= 24) {
      send(encodePong(data, performance.now()));
    } else if (kind === KIND_WORLD && data.byteLength >= 32) {
      try {
        world = parseWorld(dv, data);
      } catch (e) {
        showMessage(e.message);
        return;
      }
      noteWorldTime(world);
      HB.worldsReceived++;
      HB.lastWorldTime = world.time;
      worldsThisSecond++;
    } else if (kind === KIND_PEERS && data.byteLength >= 16) {
      try {
        peers = parsePeers(dv, data);
      } catch (e) {
        showMessage(e.message);
      }
    }
  }

  // ---------------------------------------------------------------- drawing (shared by spectator and XR)
  const tmpModel = M.create();
  // The world's frame to the headset's (local-floor): translate(-offset), set by the scene.
  const worldToHeadset = M.create();
  const FINGER_COLOR = [1.0, 0.62, 0.1, 1.0];

  // `viewProj` draws in the headset's frame (its local hands); `opts.worldViewProj`, when
  // given, draws the world's content (floor, blocks, the stepper's fingers) in it.
  function drawScene(viewProj, opts) {
    const worldViewProj = opts.worldViewProj || viewProj;
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LEQUAL);
    gl.disable(gl.CULL_FACE);
    // floor
    gl.useProgram(litProg.p);
    gl.uniformMatrix4fv(litProg.u.u_viewProj, false, worldViewProj);
    gl.uniform1f(litProg.u.u_alpha, 1);
    if (floorMesh && !opts.passthrough) {
      gl.uniformMatrix4fv(litProg.u.u_model, false, M.create());
      gl.uniform3f(litProg.u.u_color, 0.30, 0.32, 0.36);
      gl.bindVertexArray(floorMesh.vao);
      gl.drawArrays(gl.TRIANGLES, 0, floorMesh.count);
    }
    // blocks
    if (scene && world) {
      const n = Math.min(world.count, scene.blocks.length);
      for (let i = 0; i < n; i++) {
        const b = scene.blocks[i];
        if (!b.mesh) continue;
        const o = i * 8, w = world.blocks;
        if (opts.held && held.draw[i]) {
          // a held block, from this frame's hands that hold it: in the headset's frame
          gl.uniformMatrix4fv(litProg.u.u_viewProj, false, viewProj);
          gl.uniformMatrix4fv(litProg.u.u_model, false, poseMatrix(heldModel, held.drawPose, i * 7));
        } else {
          gl.uniformMatrix4fv(litProg.u.u_viewProj, false, worldViewProj);
          M.fromRTS(tmpModel, w[o + 3], w[o + 4], w[o + 5], w[o + 6], w[o], w[o + 1], w[o + 2], 1);
          gl.uniformMatrix4fv(litProg.u.u_model, false, tmpModel);
        }
        const k = w[o + 7] !== 0 ? 0.55 : 1.0;
        gl.uniform3f(litProg.u.u_color, b.color[0] * k, b.color[1] * k, b.color[2] * k);
        gl.bindVertexArray(b.mesh.vao);
        gl.drawArrays(gl.TRIANGLES, 0, b.mesh.count);
      }
    }
    // local hands (XR only), from this frame's joints: bones, joints (their radii) and palm
    if (opts.hands) {
      gl.uniformMatrix4fv(litProg.u.u_viewProj, false, viewProj);
      for (let k = 0; k < opts.hands.length; k++) {
        const h = opts.hands[k];
        if (!h.present) continue;
        const j = h.joints, color = h.left ? LEFT_HAND : RIGHT_HAND;
        const near = xrJointNear;
        if (near(j, 0) && near(j, 10)) drawHand(j, JOINT_FLOATS, XR_CHAINS, XR_PALM, 0.008, 0.008, color);
        else if (near(j, 10)) drawHand(j, JOINT_FLOATS, XR_CHAINS_NO_WRIST, XR_PALM_NO_WRIST, 0.008, 0.008, color);
        else drawHand(j, JOINT_FLOATS, XR_CHAINS_KNUCKLES, XR_PALM_KNUCKLES, 0.008, 0.008, color);
      }
    }
    // the world's hand (a spectator's view): the stepper's fingers as a hand
    HB.handBones = 0;
    if (opts.worldHand && worldHand.ready) {
      gl.uniformMatrix4fv(litProg.u.u_viewProj, false, worldViewProj);
      HB.handBones = drawHand(worldHand.pts, 3, worldHand.layout.chains, worldHand.layout.palm, WORLD_BONE_R, WORLD_JOINT_R, SKIN);
    }
    // the other participants' hands, in the world's frame
    gl.uniformMatrix4fv(litProg.u.u_viewProj, false, worldViewProj);
    HB.peerHands = peers.length;
    HB.peerBones = drawPeers();
    // grid and finger points
    gl.useProgram(flatProg.p);
    gl.uniformMatrix4fv(flatProg.u.u_viewProj, false, worldViewProj);
    if (gridLines.count) {
      gl.uniform4f(flatProg.u.u_color, 0.55, 0.58, 0.62, 1);
      gl.bindVertexArray(gridLines.vao);
      gl.drawArrays(gl.LINES, 0, gridLines.count);
    }
    if (pointsBuf.count && !(opts.worldHand && worldHand.ready)) {
      gl.uniform4f(flatProg.u.u_color, FINGER_COLOR[0], FINGER_COLOR[1], FINGER_COLOR[2], FINGER_COLOR[3]);
      gl.uniform1f(flatProg.u.u_pointSize, opts.pointSize || 6);
      gl.bindVertexArray(pointsBuf.vao);
      gl.drawArrays(gl.POINTS, 0, pointsBuf.count);
      if (fingerLines.count) {
        gl.bindVertexArray(fingerLines.vao);
        gl.drawArrays(gl.LINES, 0, fingerLines.count);
      }
    }
    gl.bindVertexArray(null);
  }

  // ---------------------------------------------------------------- hands drawn as hands
  const boneModel = M.create(), palmData = new Float32Array(PALM_FLOATS);
  const identity = M.create();

  // Draws a hand with the lit program (its viewProj set): points `pts` (x y z at `stride`
  // floats apart; the radius at offset 7 when `stride` is 8, else `boneR` and `jointR`),
  // bones along `chains` (lists of point indices), the palm a fan over `palm` (indices, the
  // first the wrist). Returns the bones drawn. Allocates nothing.
  // Whether WebXR joint i of `j` is where the hand is (near its middle knuckle).
  function xrJointNear(j, i) {
    const a = i * JOINT_FLOATS, k = 11 * JOINT_FLOATS;
    return Math.hypot(j[a] - j[k], j[a + 1] - j[k + 1], j[a + 2] - j[k + 2]) < XR_HAND_REACH;
  }
  function jointRadius(pts, stride, i, fallback) {
    return stride === 8 && pts[i * 8 + 7] > 0 ? pts[i * 8 + 7] : fallback;
  }
  function drawHand(pts, stride, chains, palm, boneR, jointR, color) {
    gl.uniform3f(litProg.u.u_color, color[0], color[1], color[2]);
    let bones = 0;
    gl.bindVertexArray(boneMesh.vao);
    for (let c = 0; c < chains.length; c++) {
      const chain = chains[c];
      for (let k = 0; k + 1 < chain.length; k++) {
        const a = chain[k] * stride, b = chain[k + 1] * stride;
        // the finer of the two joints' radii, a little less: the joints stand out
        const r = 0.8 * Math.min(jointRadius(pts, stride, chain[k], boneR / 0.8),
          jointRadius(pts, stride, chain[k + 1], boneR / 0.8));
        if (!boneMatrix(boneModel, pts[a], pts[a + 1], pts[a + 2], pts[b], pts[b + 1], pts[b + 2], r)) continue;
        gl.uniformMatrix4fv(litProg.u.u_model, false, boneModel);
        gl.drawArrays(gl.TRIANGLES, 0, boneMesh.count);
        bones++;
      }
    }
    gl.bindVertexArray(jointMesh.vao);
    for (let c = 0; c < chains.length; c++) {
      const chain = chains[c];
      // a joint the chains share (the wrist) once
      for (let k = c > 0 && chain[0] === chains[0][0] ? 1 : 0; k < chain.length; k++) {
        const i = chain[k], o = i * stride;
        M.fromRTS(boneModel, 0, 0, 0, 1, pts[o], pts[o + 1], pts[o + 2], jointRadius(pts, stride, i, jointR));
        gl.uniformMatrix4fv(litProg.u.u_model, false, boneModel);
        gl.drawArrays(gl.TRIANGLES, 0, jointMesh.count);
      }
    }
    // the palm: triangles (wrist, corner k, corner k + 1), each lit from above
    const n = Math.min(palm.length, PALM_MAX_CORNERS);
    let f = 0;
    const w = palm[0] * stride;
    for (let k = 1; k + 1 < n; k++) {
      const a = palm[k] * stride, b = palm[k + 1] * stride;
      const ux = pts[a] - pts[w], uy = pts[a + 1] - pts[w + 1], uz = pts[a + 2] - pts[w + 2];
      const vx = pts[b] - pts[w], vy = pts[b + 1] - pts[w + 1], vz = pts[b + 2] - pts[w + 2];
      let nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      const l = (ny < 0 ? -1 : 1) * (Math.hypot(nx, ny, nz) || 1);
      nx /= l; ny /= l; nz /= l;
      for (let v = 0; v < 3; v++) {
        const q = v === 0 ? w : v === 1 ? a : b;
        palmData[f++] = pts[q]; palmData[f++] = pts[q + 1]; palmData[f++] = pts[q + 2];
        palmData[f++] = nx; palmData[f++] = ny; palmData[f++] = nz;
      }
    }
    if (f > 0) {
      gl.bindBuffer(gl.ARRAY_BUFFER, palmBuf.buf);
      gl.bufferSubData(gl.ARRAY_BUFFER, 0, palmData, 0, f);
      gl.uniformMatrix4fv(litProg.u.u_model, false, identity);
      gl.uniform3f(litProg.u.u_color, color[0] * 0.92, color[1] * 0.92, color[2] * 0.92);
      gl.bindVertexArray(palmBuf.vao);
      gl.drawArrays(gl.TRIANGLES, 0, f / 6);
    }
    return bones;
  }

  // The world's fingers as a hand. The world carries the check points as the stepper drew
  // them (docs/model.md R5: moved onto a grasped block's surface), per finger knuckle to tip,
  // without their counts; the joints model (a headset's, a CARL trace's) has 19: the thumb's
  // 3, then 4 for each finger. The wrist is not among them: it is put behind the middle
  // knuckle, away from the fingers, by the palm's length (1.55 times the knuckles' span), in
  // the direction of the thumb's base knuckle across the knuckles' line.
  const worldHand = {
    layout: null,           // handLayout(its points), or null: none drawable
    pts: new Float32Array(3 * 64),
    ready: false,           // pts holds the newest world's hand
  };
  // The chains and palm of a hand of `points` finger points (19: the joints model's; 5 equal
  // fingers of up to 5: a glove's), the wrist one point past them; null for another count.
  // Made once per count.
  const layouts = new Map();
  function handLayout(points) {
    if (layouts.has(points)) return layouts.get(points);
    const counts = points === 19 ? [3, 4, 4, 4, 4] : points > 0 && points % 5 === 0 && points <= 25
      ? [points / 5, points / 5, points / 5, points / 5, points / 5] : null;
    let layout = null;
    if (counts) {
      const wrist = points, starts = [];
      let at = 0;
      const chains = counts.map((c) => {
        starts.push(at);
        const chain = [wrist];
        for (let k = 0; k < c; k++) chain.push(at + k);
        at += c;
        return chain;
      });
      layout = { points, chains, palm: [wrist, starts[0], starts[1], starts[2], starts[3], starts[4]], wrist };
    }
    layouts.set(points, layout);
    return layout;
  }
  // Puts the wrist into `p` (x y z per point, the finger points first) for `layout`: the
  // palm's outline is the wrist, the thumb's base knuckle, then index ... pinky knuckles.
  // False when the knuckles give no direction (then the hand is not drawn).
  function placeWrist(p, layout) {
    const pal = layout.palm;
    const t = pal[1] * 3, ix = pal[2] * 3, mx = pal[3] * 3, px = pal[5] * 3;
    // across the knuckles, and the thumb's base knuckle's offset from the middle one square
    // to that line: the way to the wrist
    let ax = p[ix] - p[px], ay = p[ix + 1] - p[px + 1], az = p[ix + 2] - p[px + 2];
    const span = Math.hypot(ax, ay, az) || 1;
    ax /= span; ay /= span; az /= span;
    let bx = p[t] - p[mx], by = p[t + 1] - p[mx + 1], bz = p[t + 2] - p[mx + 2];
    const along = bx * ax + by * ay + bz * az;
    bx -= along * ax; by -= along * ay; bz -= along * az;
    const bl = Math.hypot(bx, by, bz);
    if (!(bl > 1e-6)) return false;
    const len = Math.min(0.12, Math.max(0.06, 1.55 * span));
    const w = layout.wrist * 3;
    p[w] = p[mx] + bx / bl * len; p[w + 1] = p[mx + 1] + by / bl * len; p[w + 2] = p[mx + 2] + bz / bl * len;
    return true;
  }
  function prepareWorldHand() {
    worldHand.ready = false;
    const layout = world ? handLayout(world.points) : null;
    worldHand.layout = layout;
    if (!layout) return;
    const p = worldHand.pts, f = world.fingers, n = world.points;
    if (3 * (n + 1) > p.length) return;
    for (let i = 0; i < 3 * n; i++) p[i] = f[i];
    worldHand.ready = placeWrist(p, layout);
  }

  // ---------------------------------------------------------------- the other participants' hands
  // In a shared world (docs/sessions.md "Shared sessions"), the others' hands as the server
  // sends them (kind 6): each drawn as a hand in its participant's colour, in the world's
  // frame, as the stepper's hand is. A message replaces the last; one with no hands clears.
  const PEER_COLORS = [[0.55, 0.85, 0.45], [0.95, 0.55, 0.75], [0.7, 0.6, 0.95], [0.95, 0.85, 0.4]];
  // the left hand a little darker
  const PEER_COLORS_LEFT = PEER_COLORS.map((c) => c.map((v) => v * 0.85));
  let peers = [];
  function parsePeers(dv, buf) {
    const count = dv.getUint32(8, true);
    if (count > 6) throw new Error(`peers message of ${count} hands, at most 6`);
    const hands = [];
    let at = 16;
    for (let h = 0; h < count; h++) {
      if (buf.byteLength < at + 8) throw new Error(`peers message of ${buf.byteLength} bytes, cut short`);
      const participant = dv.getUint32(at, true), side = dv.getUint16(at + 4, true);
      const points = dv.getUint16(at + 6, true);
      if (points > 25) throw new Error(`peer hand of ${points} points, at most 25`);
      at += 8;
      if (buf.byteLength < at + 12 * points) throw new Error(`peers message of ${buf.byteLength} bytes, cut short`);
      // the finger points, then room for the wrist (placeWrist)
      const pts = new Float32Array(3 * (points + 1));
      for (let i = 0; i < 3 * points; i++) pts[i] = dv.getFloat32(at + 4 * i, true);
      at += 12 * points;
      const layout = handLayout(points);
      const drawable = layout !== null && pts.every(Number.isFinite) && placeWrist(pts, layout);
      hands.push({ participant, side, points, pts, layout: drawable ? layout : null });
    }
    if (at !== buf.byteLength) throw new Error(`peers message of ${buf.byteLength} bytes, expected ${at}`);
    return hands;
  }
  // Draws the others' hands (the lit program in use, the world's viewProj set): the bones drawn.
  function drawPeers() {
    let bones = 0;
    for (const h of peers) {
      if (!h.layout) continue;
      const color = (h.side === 1 ? PEER_COLORS_LEFT : PEER_COLORS)[h.participant % PEER_COLORS.length];
      bones += drawHand(h.pts, 3, h.layout.chains, h.layout.palm, WORLD_BONE_R, WORLD_JOINT_R, color);
    }
    return bones;
  }

  // Upload the newest world's finger points (points, and short crosses so they read at any size).
  let uploadedWorld = null;
  function uploadWorldPoints() {
    if (!world || uploadedWorld === world) return;
    uploadedWorld = world;
    fillDynamic(pointsBuf, world.fingers, world.points);
    const s = 0.006, f = world.fingers, cross = new Float32Array(world.points * 18);
    for (let i = 0, o = 0; i < world.points; i++) {
      const x = f[3 * i], y = f[3 * i + 1], z = f[3 * i + 2];
      cross.set([x - s, y, z, x + s, y, z, x, y - s, z, x, y + s, z, x, y, z - s, x, y, z + s], o);
      o += 18;
    }
    fillDynamic(fingerLines, cross, world.points * 6);
    prepareWorldHand();
  }

  // ---------------------------------------------------------------- spectator view
  const orbit = Object.assign(orbitCamera(canvas, { yaw: 0.35, pitch: 0.42, dist: 0.6, target: [0, 0.9, -0.4] }),
    { autoTarget: true, aimedAt: null });

  const specView = M.create(), specProj = M.create(), specViewProj = M.create();
  let xrSession = null;

  function resizeCanvas() {
    const dpr = Math.min(window.devicePixelRatio || 1, 2);
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  }

  // `12.35 s`, or `2:05.40` (2 min 5.40 s) from a minute on.
  function sessionTime(seconds) {
    if (!Number.isFinite(seconds)) return '-';
    if (seconds < 60) return seconds.toFixed(2) + ' s';
    const m = Math.floor(seconds / 60), rest = seconds - 60 * m;
    return `${m}:${rest < 10 ? '0' : ''}${rest.toFixed(2)}`;
  }

  function updateOverlay(now) {
    if (now - worldRateStart >= 1000) {
      worldsPerSecond = worldsThisSecond * 1000 / (now - worldRateStart);
      worldsThisSecond = 0;
      worldRateStart = now;
    }
    // The session's time: the world's steps over its rate, which count from the session's
    // first hand sample (world time 0, docs/model.md "Conventions"), not a clock's reading.
    const t = world ? sessionTime(world.time) : '- (no hand yet)';
    const g = world && world.grasped >= 0 && scene && scene.blocks[world.grasped] ? ', grasped: ' + scene.blocks[world.grasped].name : '';
    const rate = worldsPerSecond === null ? '-' : worldsPerSecond.toFixed(1);
    worldLine.textContent = `Session time: ${t}, ${rate} worlds/s${g}`;
  }

  function spectatorFrame() {
    if (xrSession) return;            // the XR loop draws while a session runs
    window.requestAnimationFrame(spectatorFrame);
    const now = performance.now();
    updateOverlay(now);
    if (!gl) { noteWorldDrawn(now); return; }
    resizeCanvas();
    if (orbit.autoTarget && world && world !== orbit.aimedAt && scene && world.count + world.points > 0) {
      orbit.aimedAt = world;
      // Aim at the middle of the blocks and the hand, near enough that both fill the view;
      // once a hand is seen the user's orbit is left alone.
      let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
      const take = (a, o) => {
        for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], a[o + k]); hi[k] = Math.max(hi[k], a[o + k]); }
      };
      for (let i = 0; i < world.count; i++) take(world.blocks, i * 8);
      for (let i = 0; i < world.points; i++) take(world.fingers, i * 3);
      if (lo.every(Number.isFinite) && hi.every(Number.isFinite)) {
        frameBox(orbit, lo, hi);
      }
      if (world.points > 0) orbit.autoTarget = false;
    }
    orbitViewProj(orbit, canvas.width / canvas.height, specView, specProj, specViewProj);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(0.13, 0.14, 0.17, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    uploadWorldPoints();
    drawScene(specViewProj, { pointSize: 7, worldHand: true });
    noteWorldDrawn(performance.now());
  }

  // ---------------------------------------------------------------- XR
  let xrRefSpace = null;
  let frameSeq = 0;                 // seq of the last hands message sent
  let prevStats = null;             // { seq, jsMs } of the previous frame that sent hands
  const hands = [
    { left: true, present: false, joints: new Float32Array(JOINT_COUNT * JOINT_FLOATS) },
    { left: false, present: false, joints: new Float32Array(JOINT_COUNT * JOINT_FLOATS) },
  ];
  const xrViewProj = M.create();
  const xrWorldViewProj = M.create();

  // Read one hand's 25 joints through getJointPose: its transform.position / .orientation carry
  // the runtime's pose as given (no matrix -> quaternion round trip in the page).
  function readHand(frame, hand, out) {
    for (let i = 0; i < JOINT_COUNT; i++) {
      const space = hand.get(JOINTS[i]);
      if (!space) return false;
      const pose = frame.getJointPose(space, xrRefSpace);
      if (!pose) return false;
      const p = pose.transform.position, q = pose.transform.orientation, o = i * 8;
      out[o] = p.x; out[o + 1] = p.y; out[o + 2] = p.z;
      out[o + 3] = q.x; out[o + 4] = q.y; out[o + 5] = q.z; out[o + 6] = q.w;
      out[o + 7] = pose.radius;
    }
    return true;
  }

  function sendHands(frameTime, mask) {
    const seq = frameSeq + 1;
    if (!send(encodeHands(seq, frameTime, mask, [hands[0].joints, hands[1].joints]))) return 0;
    frameSeq = seq;
    noteWristSent(seq, frameTime, mask);
    ringSeq[seq % RING] = seq;
    ringTime[seq % RING] = performance.now();
    HB.framesSent++;
    return seq;
  }

  function sendStats(seq, jsMs, roundTripMs) {
    send(encodeStats(seq, jsMs, roundTripMs));
  }

  let handSeen = false;

  function onXRFrame(t, frame) {
    const t0 = performance.now();
    const session = frame.session;
    session.requestAnimationFrame(onXRFrame);

    // 1. the hands, read and sent first so that drawing never delays them
    let mask = 0;
    hands[0].present = hands[1].present = false;
    for (const source of session.inputSources) {
      if (!source.hand) continue;
      const h = source.handedness === 'left' ? 0 : source.handedness === 'right' ? 1 : -1;
      if (h < 0 || hands[h].present) continue;
      if (readHand(frame, source.hand, hands[h].joints)) { hands[h].present = true; mask |= 1 << h; }
    }
    // Once a hand was seen, every frame is sent, a frame without a hand too (mask 0): the
    // session holds a lost hand's grasp for a stated time, and it measures that time by frames.
    if (mask) handSeen = true;
    let seq = 0;
    if (mask || handSeen) {
      if (HB.ready && ws && ws.readyState === WebSocket.OPEN) {
        const xrTime = typeof frame.predictedDisplayTime === 'number' ? frame.predictedDisplayTime : t;
        const frameTime = typeof HB.frameTimeOverride === 'function' ? Number(HB.frameTimeOverride(xrTime)) : xrTime;
        seq = sendHands(frameTime, mask);
      } else {
        HB.framesSkipped++;
      }
    }
    // 2. the previous hands frame's own timing
    if (prevStats) {
      sendStats(prevStats.seq, prevStats.jsMs, pendingRoundTrip);
      pendingRoundTrip = -1;
      prevStats = null;
    }

    // 3. draw every view
    const layer = session.renderState.baseLayer;
    const viewer = xrRefSpace ? frame.getViewerPose(xrRefSpace) : null;
    if (gl && layer && viewer) {
      gl.bindFramebuffer(gl.FRAMEBUFFER, layer.framebuffer);
      const passthrough = HB.xrMode === 'immersive-ar';
      if (passthrough) gl.clearColor(0, 0, 0, 0); else gl.clearColor(0.13, 0.14, 0.17, 1);
      gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
      uploadWorldPoints();
      prepareHeld(seq);
      for (const view of viewer.views) {
        const vp = layer.getViewport(view);
        if (!vp) continue;
        gl.viewport(vp.x, vp.y, vp.width, vp.height);
        M.multiply(xrViewProj, view.projectionMatrix, view.transform.inverse.matrix);
        M.multiply(xrWorldViewProj, xrViewProj, worldToHeadset);
        drawScene(xrViewProj, { hands, passthrough, pointSize: 5, worldViewProj: xrWorldViewProj, held: heldDraw });
      }
      noteWorldDrawn(performance.now());
    }
    updateOverlay(t0);

    const jsMs = performance.now() - t0;
    keep(HB.stats.jsMs, jsMs);
    if (seq) prevStats = { seq, jsMs };
  }

  async function enterXR(mode) {
    if (xrSession) return;
    try {
      const session = await navigator.xr.requestSession(mode, {
        requiredFeatures: ['local-floor'], optionalFeatures: ['hand-tracking'],
      });
      if (gl.makeXRCompatible) await gl.makeXRCompatible();
      session.updateRenderState({ baseLayer: new XRWebGLLayer(session, gl) });
      xrRefSpace = await session.requestReferenceSpace('local-floor');
      xrSession = session;
      HB.xrMode = mode;
      vrButton.hidden = arButton.hidden = true;
      xrLine.textContent = `WebXR: in ${mode}` + (session.enabledFeatures && !session.enabledFeatures.includes('hand-tracking') ? ' (no hand tracking granted)' : '');
      session.addEventListener('end', () => {
        xrSession = null; xrRefSpace = null; HB.xrMode = null; prevStats = null;
        xrLine.textContent = 'WebXR: session ended';
        checkXR();
        window.requestAnimationFrame(spectatorFrame);
      });
      session.requestAnimationFrame(onXRFrame);
    } catch (e) {
      showMessage(`could not enter ${mode}: ${e.message || e}`);
    }
  }

  async function checkXR() {
    if (!navigator.xr) {
      xrLine.textContent = window.isSecureContext ? 'WebXR: not in this browser (spectator view)'
        : 'WebXR: needs https:// or http://localhost (spectator view)';
      return;
    }
    let vr = false, ar = false;
    try { vr = await navigator.xr.isSessionSupported('immersive-vr'); } catch (e) { vr = false; }
    try { ar = await navigator.xr.isSessionSupported('immersive-ar'); } catch (e) { ar = false; }
    vrButton.hidden = !vr || !gl;
    arButton.hidden = !ar || !gl;
    xrLine.textContent = vr || ar ? 'WebXR: available' + (vr ? ' (VR' + (ar ? ', AR)' : ')') : ' (AR)')
      : 'WebXR: no immersive session here (spectator view)';
  }
  vrButton.addEventListener('click', () => enterXR('immersive-vr'));
  arButton.addEventListener('click', () => enterXR('immersive-ar'));

  // ---------------------------------------------------------------- start
  buildFloor(0);
  checkXR();
  connect();
  window.requestAnimationFrame(spectatorFrame);
})();
