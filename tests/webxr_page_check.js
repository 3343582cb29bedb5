// The headset page's own decoders and encoders (services/webxr/page/app.js, `window.handblocks
// .wire`) against the protocol as Rust declares it (common/webxr-wire): tests/webxr_browser.rs
// writes every message the page is sent, and the values of every message it sends, as
// webxr-wire makes them; this opens the page in headless Chromium (files served from PAGE_DIR,
// no server: its socket never connects), passes each through the page's functions, and prints
// what they read and wrote, in webxr-wire's terms, for the test to compare.
//
//   NODE_PATH=target/webxr-node/node_modules node tests/webxr_page_check.js PAGE_DIR MESSAGES.json
//
// MESSAGES.json: { scene, ready (text), world, peers, ping (bytes as arrays of numbers), arrived (the
// pong's page time), hands: [{ seq, frameTime, mask, joints: [left 200 numbers, right 200] }],
// stats: [{ seq, jsMs, roundTripMs }] }. Prints one JSON line: { scene (page::Scene's JSON),
// ready (page::Ready's), world (page::World's), peers ([page::PeerHand]), peerHands and
// peerBones (what the page drew of them), pong, hands, stats (bytes) } or { error }.
'use strict';

const fs = require('fs');
const path = require('path');

const [pageDir, messagesFile] = process.argv.slice(2);
const done = (out, code) => {
  process.stdout.write(JSON.stringify(out) + '\n');
  process.exit(code);
};
if (!pageDir || !messagesFile) done({ error: 'usage: webxr_page_check.js PAGE_DIR MESSAGES.json' }, 2);
setTimeout(() => done({ error: 'timed out' }), Number(process.env.HB_PAGE_CHECK_TIMEOUT_MS || 60000)).unref();

const TYPES = { '.html': 'text/html; charset=utf-8', '.js': 'text/javascript; charset=utf-8' };

async function main() {
  const { chromium } = require('playwright-core');
  const messages = JSON.parse(fs.readFileSync(messagesFile, 'utf8'));
  const browser = await chromium.launch({
    executablePath: process.env.HB_CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: ['--no-sandbox', '--disable-gpu', '--no-first-run', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader', '--host-resolver-rules=MAP * ~NOTFOUND'],
  });
  try {
    const page = await browser.newPage();
    const errors = [];
    page.on('pageerror', (e) => errors.push(String(e)));
    // The page's files as the server serves them ("/" is index.html); nothing else.
    await page.route('http://handblocks.test/**', (route) => {
      const name = new URL(route.request().url()).pathname.replace(/^\/$/, '/index.html');
      const file = path.join(pageDir, path.basename(name));
      if (!fs.existsSync(file)) return route.fulfill({ status: 404, body: 'not found' });
      return route.fulfill({ status: 200, contentType: TYPES[path.extname(file)] || 'text/plain',
        body: fs.readFileSync(file) });
    });
    await page.goto('http://handblocks.test/?token=page-check', { waitUntil: 'load' });
    await page.waitForFunction(() => window.handblocks && window.handblocks.wire, null, { timeout: 30000 });
    const out = await page.evaluate(async (m) => {
      const wire = window.handblocks.wire;
      const buffer = (bytes) => new Uint8Array(bytes).buffer;
      const bytes = (buf) => Array.from(new Uint8Array(buf));
      const list = (v) => (v === null ? null : Array.from(v));
      // The page's scene and ready, back in page::Scene's and page::Ready's terms.
      const s = wire.text(m.scene).scene;
      const scene = {
        blocks: s.blocks.map((b) => ({ color: b.color, indices: list(b.indices), name: b.name,
          vertices: list(b.vertices) })),
        floor_y: s.floorY, hand: s.hand, offset: s.offset, op: 'scene', session: s.session,
        step_hz: s.stepHz,
      };
      const r = wire.text(m.ready);
      const ready = { op: r.op, offset_ms: r.offsetMs, round_trip_ms: r.roundTripMs };
      // The world as the page keeps it (8 numbers a block: pose, mode; holders apart).
      const w = wire.world(buffer(m.world));
      const world = {
        page_seq: w.pageSeq, time_s: w.time, grasped: w.grasped,
        blocks: Array.from({ length: w.count }, (_, i) => ({
          position: Array.from(w.blocks.subarray(i * 8, i * 8 + 3)),
          rotation: Array.from(w.blocks.subarray(i * 8 + 3, i * 8 + 7)),
          mode: w.blocks[i * 8 + 7], held_by: w.heldBy[i],
        })),
        finger_points: Array.from({ length: w.points }, (_, i) => Array.from(w.fingers.subarray(i * 3, i * 3 + 3))),
      };
      // The others' hands as the page keeps them (page::PeerHand's terms), then as it draws
      // them: the message through the page's own socket handler, and two frames drawn.
      const peers = wire.peers(buffer(m.peers)).map((h) => ({ participant: h.participant,
        side: h.side, points: Array.from({ length: h.points }, (_, i) => Array.from(h.pts.subarray(i * 3, i * 3 + 3))) }));
      wire.receive(buffer(m.peers));
      const frame = () => new Promise((resolve) => window.requestAnimationFrame(resolve));
      await frame();
      await frame();
      const hb = window.handblocks;
      return {
        scene, ready, world, peers, peerHands: hb.peerHands, peerBones: hb.peerBones,
        unknownOp: wire.text('{"op":"error","message":"x"}'),
        pong: bytes(wire.pong(buffer(m.ping), m.arrived)),
        hands: m.hands.map((h) => bytes(wire.hands(h.seq, h.frameTime, h.mask,
          h.joints.map((j) => Float32Array.from(j))))),
        stats: m.stats.map((s) => bytes(wire.stats(s.seq, s.jsMs, s.roundTripMs))),
      };
    }, messages);
    if (errors.length) out.pageErrors = errors;
    return out;
  } finally {
    await browser.close();
  }
}

main().then((out) => done(out, 0)).catch((e) => done({ error: String(e && e.stack || e) }, 1));
