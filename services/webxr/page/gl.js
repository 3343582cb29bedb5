// handblocks page: the matrices, meshes and orbit camera the page draws with (app.js imports
// them). Our own code, moved out of app.js so that app.js holds the page (its protocol, state
// and drawing) and this the geometry; served from the binary beside it, nothing fetched.
// Matrices are column-major Float32Array(16); a pose is 7 numbers: position x y z, then the
// unit quaternion x y z w.
'use strict';

// ---------------------------------------------------------------- small matrix library (column-major)
export const M = {
  create() { const m = new Float32Array(16); m[0] = m[5] = m[10] = m[15] = 1; return m; },
  multiply(out, a, b) {
    const r = new Float32Array(16);
    for (let c = 0; c < 4; c++) {
      for (let rw = 0; rw < 4; rw++) {
        r[c * 4 + rw] = a[rw] * b[c * 4] + a[4 + rw] * b[c * 4 + 1] + a[8 + rw] * b[c * 4 + 2] + a[12 + rw] * b[c * 4 + 3];
      }
    }
    out.set(r);
    return out;
  },
  perspective(out, fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    out.fill(0);
    out[0] = f / aspect; out[5] = f; out[10] = (far + near) * nf; out[11] = -1; out[14] = 2 * far * near * nf;
    return out;
  },
  lookAt(out, eye, at, up) {
    let zx = eye[0] - at[0], zy = eye[1] - at[1], zz = eye[2] - at[2];
    let l = Math.hypot(zx, zy, zz) || 1; zx /= l; zy /= l; zz /= l;
    let xx = up[1] * zz - up[2] * zy, xy = up[2] * zx - up[0] * zz, xz = up[0] * zy - up[1] * zx;
    l = Math.hypot(xx, xy, xz) || 1; xx /= l; xy /= l; xz /= l;
    const yx = zy * xz - zz * xy, yy = zz * xx - zx * xz, yz = zx * xy - zy * xx;
    out[0] = xx; out[1] = yx; out[2] = zx; out[3] = 0;
    out[4] = xy; out[5] = yy; out[6] = zy; out[7] = 0;
    out[8] = xz; out[9] = yz; out[10] = zz; out[11] = 0;
    out[12] = -(xx * eye[0] + xy * eye[1] + xz * eye[2]);
    out[13] = -(yx * eye[0] + yy * eye[1] + yz * eye[2]);
    out[14] = -(zx * eye[0] + zy * eye[1] + zz * eye[2]);
    out[15] = 1;
    return out;
  },
  // translate(p) * rotate(q) * scale(s)
  fromRTS(out, qx, qy, qz, qw, px, py, pz, s) {
    const n = Math.hypot(qx, qy, qz, qw) || 1;
    qx /= n; qy /= n; qz /= n; qw /= n;
    const x2 = qx + qx, y2 = qy + qy, z2 = qz + qz;
    const xx = qx * x2, yx = qy * x2, yy = qy * y2, zx = qz * x2, zy = qz * y2, zz = qz * z2;
    const wx = qw * x2, wy = qw * y2, wz = qw * z2;
    out[0] = (1 - yy - zz) * s; out[1] = (yx + wz) * s; out[2] = (zx - wy) * s; out[3] = 0;
    out[4] = (yx - wz) * s; out[5] = (1 - xx - zz) * s; out[6] = (zy + wx) * s; out[7] = 0;
    out[8] = (zx + wy) * s; out[9] = (zy - wx) * s; out[10] = (1 - xx - yy) * s; out[11] = 0;
    out[12] = px; out[13] = py; out[14] = pz; out[15] = 1;
    return out;
  },
};

// ---------------------------------------------------------------- WebGL2 programs and meshes
// A program of `vsSrc` and `fsSrc`, its attributes a_pos (0) and a_normal (1), and its uniforms
// by name (`u`).
function compile(gl, vsSrc, fsSrc) {
  const mk = (type, src) => {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error('shader: ' + gl.getShaderInfoLog(s));
    return s;
  };
  const p = gl.createProgram();
  gl.attachShader(p, mk(gl.VERTEX_SHADER, vsSrc));
  gl.attachShader(p, mk(gl.FRAGMENT_SHADER, fsSrc));
  gl.bindAttribLocation(p, 0, 'a_pos');
  gl.bindAttribLocation(p, 1, 'a_normal');
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error('program: ' + gl.getProgramInfoLog(p));
  const u = {};
  const n = gl.getProgramParameter(p, gl.ACTIVE_UNIFORMS);
  for (let i = 0; i < n; i++) {
    const info = gl.getActiveUniform(p, i);
    u[info.name] = gl.getUniformLocation(p, info.name);
  }
  return { p, u };
}

// The page's two programs: `lit`, flat-shaded triangles lit from two directions (u_color,
// u_alpha, u_model, u_viewProj), and `flat`, lines and points of one colour (u_color,
// u_pointSize, u_viewProj).
export function programs(gl) {
  const lit = compile(gl, `#version 300 es
    layout(location=0) in vec3 a_pos;
    layout(location=1) in vec3 a_normal;
    uniform mat4 u_viewProj; uniform mat4 u_model;
    out vec3 v_normal;
    void main() {
      v_normal = mat3(u_model) * a_normal;
      gl_Position = u_viewProj * u_model * vec4(a_pos, 1.0);
    }`, `#version 300 es
    precision mediump float;
    in vec3 v_normal; uniform vec3 u_color; uniform float u_alpha;
    out vec4 o_color;
    void main() {
      vec3 n = normalize(v_normal);
      float d = max(dot(n, normalize(vec3(0.35, 0.9, 0.45))), 0.0);
      float b = max(dot(n, normalize(vec3(-0.5, 0.2, -0.6))), 0.0);
      o_color = vec4(u_color * (0.38 + 0.55 * d + 0.12 * b), u_alpha);
    }`);
  const flat = compile(gl, `#version 300 es
    layout(location=0) in vec3 a_pos;
    uniform mat4 u_viewProj; uniform float u_pointSize;
    void main() { gl_Position = u_viewProj * vec4(a_pos, 1.0); gl_PointSize = u_pointSize; }`, `#version 300 es
    precision mediump float;
    uniform vec4 u_color; out vec4 o_color;
    void main() { o_color = u_color; }`);
  return { lit, flat };
}

// The mesh functions on `gl`: static flat-shaded meshes, and dynamic buffers for lines and
// points and for lit triangles.
export function meshes(gl) {
  // A flat-shaded mesh: triangles un-indexed, one normal per face.
  function makeMesh(vertices, indices) {
    const tris = Math.floor(indices.length / 3);
    const data = new Float32Array(tris * 18);
    let o = 0;
    for (let t = 0; t < tris; t++) {
      const ia = indices[3 * t] * 3, ib = indices[3 * t + 1] * 3, ic = indices[3 * t + 2] * 3;
      const ax = vertices[ia], ay = vertices[ia + 1], az = vertices[ia + 2];
      const bx = vertices[ib], by = vertices[ib + 1], bz = vertices[ib + 2];
      const cx = vertices[ic], cy = vertices[ic + 1], cz = vertices[ic + 2];
      const ux = bx - ax, uy = by - ay, uz = bz - az, vx = cx - ax, vy = cy - ay, vz = cz - az;
      let nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      const l = Math.hypot(nx, ny, nz) || 1; nx /= l; ny /= l; nz /= l;
      for (const [x, y, z] of [[ax, ay, az], [bx, by, bz], [cx, cy, cz]]) {
        data[o++] = x; data[o++] = y; data[o++] = z; data[o++] = nx; data[o++] = ny; data[o++] = nz;
      }
    }
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 24, 0);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 24, 12);
    gl.bindVertexArray(null);
    return { vao, buf, count: tris * 3 };
  }
  function freeMesh(m) { if (m) { gl.deleteVertexArray(m.vao); gl.deleteBuffer(m.buf); } }

  // A dynamic position-only buffer for lines and points.
  function makeDynamic() {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 12, 0);
    gl.bindVertexArray(null);
    return { vao, buf, count: 0 };
  }
  function fillDynamic(d, floats, count) {
    gl.bindBuffer(gl.ARRAY_BUFFER, d.buf);
    gl.bufferData(gl.ARRAY_BUFFER, floats, gl.DYNAMIC_DRAW);
    d.count = count;
  }
  // A dynamic buffer of lit triangles (position, normal) of at most `floats` floats, made once.
  function makeLitDynamic(floats) {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf);
    gl.bufferData(gl.ARRAY_BUFFER, floats * 4, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 24, 0);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 24, 12);
    gl.bindVertexArray(null);
    return { vao, buf, count: 0 };
  }
  return { makeMesh, freeMesh, makeDynamic, fillDynamic, makeLitDynamic };
}

// Unit shapes, as [vertices, indices] for meshes().
// A bone: a unit prism of `sides` faces along +y, from y = 0 to 1, radius 1 (stretched
// between two joints by boneMatrix).
export function prism(sides) {
  const v = [], idx = [];
  for (let k = 0; k < sides; k++) {
    const a = 2 * Math.PI * k / sides;
    v.push(Math.cos(a), 0, Math.sin(a), Math.cos(a), 1, Math.sin(a));
  }
  for (let k = 0; k < sides; k++) {
    const a = 2 * k, b = 2 * ((k + 1) % sides);
    idx.push(a, a + 1, b, b, a + 1, b + 1);   // wound outwards (the lit shader's normals)
    if (k > 0 && k + 1 < sides) idx.push(0, a, b, 1, b + 1, a + 1);
  }
  return [v, idx];
}
// A joint: a unit sphere of `seg` x `rings` facets.
export function sphere(seg, rings) {
  const v = [], idx = [];
  for (let r = 0; r <= rings; r++) {
    const th = Math.PI * r / rings;
    for (let k = 0; k < seg; k++) {
      const ph = 2 * Math.PI * k / seg;
      v.push(Math.sin(th) * Math.cos(ph), Math.cos(th), Math.sin(th) * Math.sin(ph));
    }
  }
  for (let r = 0; r < rings; r++) {
    for (let k = 0; k < seg; k++) {
      const a = r * seg + k, b = r * seg + (k + 1) % seg;
      idx.push(a, b, a + seg, b, b + seg, a + seg);
    }
  }
  return [v, idx];
}

// out = the bone from a to b of radius r: the unit prism's x and z scaled by r, its y
// along b - a. False for a bone of no length.
export function boneMatrix(out, ax, ay, az, bx, by, bz, r) {
  const dx = bx - ax, dy = by - ay, dz = bz - az;
  const len = Math.hypot(dx, dy, dz);
  if (!(len > 1e-6)) return false;
  const yx = dx / len, yy = dy / len, yz = dz / len;
  // x: across the bone (any direction not along it), z = x cross y
  const px = Math.abs(yz) > 0.9 ? 1 : 0, pz = 1 - px;
  let xx = -pz * yy, xy = pz * yx - px * yz, xz = px * yy;
  const xl = Math.hypot(xx, xy, xz);
  xx /= xl; xy /= xl; xz /= xl;
  const zx = xy * yz - xz * yy, zy = xz * yx - xx * yz, zz = xx * yy - xy * yx;
  out[0] = xx * r; out[1] = xy * r; out[2] = xz * r; out[3] = 0;
  out[4] = dx; out[5] = dy; out[6] = dz; out[7] = 0;
  out[8] = zx * r; out[9] = zy * r; out[10] = zz * r; out[11] = 0;
  out[12] = ax; out[13] = ay; out[14] = az; out[15] = 1;
  return true;
}

// ---------------------------------------------------------------- poses (rigid transforms)
// out[o..o+7] = a[ao..] * b[bo..] (rigid transforms; out may not alias a or b)
export function poseMul(out, o, a, ao, b, bo) {
  const ax = a[ao + 3], ay = a[ao + 4], az = a[ao + 5], aw = a[ao + 6];
  const bx = b[bo + 3], by = b[bo + 4], bz = b[bo + 5], bw = b[bo + 6];
  rotate(out, o, ax, ay, az, aw, b[bo], b[bo + 1], b[bo + 2]);
  out[o] += a[ao]; out[o + 1] += a[ao + 1]; out[o + 2] += a[ao + 2];
  out[o + 3] = aw * bx + ax * bw + ay * bz - az * by;
  out[o + 4] = aw * by - ax * bz + ay * bw + az * bx;
  out[o + 5] = aw * bz + ax * by - ay * bx + az * bw;
  out[o + 6] = aw * bw - ax * bx - ay * by - az * bz;
}
// out = a^-1 * b
export function poseInvMul(out, o, a, ao, b, bo) {
  const ax = -a[ao + 3], ay = -a[ao + 4], az = -a[ao + 5], aw = a[ao + 6];
  const bx = b[bo + 3], by = b[bo + 4], bz = b[bo + 5], bw = b[bo + 6];
  rotate(out, o, ax, ay, az, aw, b[bo] - a[ao], b[bo + 1] - a[ao + 1], b[bo + 2] - a[ao + 2]);
  out[o + 3] = aw * bx + ax * bw + ay * bz - az * by;
  out[o + 4] = aw * by - ax * bz + ay * bw + az * bx;
  out[o + 5] = aw * bz + ax * by - ay * bx + az * bw;
  out[o + 6] = aw * bw - ax * bx - ay * by - az * bz;
}
// out[o..o+3] = q * v (q unit)
export function rotate(out, o, qx, qy, qz, qw, vx, vy, vz) {
  const tx = 2 * (qy * vz - qz * vy), ty = 2 * (qz * vx - qx * vz), tz = 2 * (qx * vy - qy * vx);
  out[o] = vx + qw * tx + (qy * tz - qz * ty);
  out[o + 1] = vy + qw * ty + (qz * tx - qx * tz);
  out[o + 2] = vz + qw * tz + (qx * ty - qy * tx);
}
export function normalizeQuat(p, o) {
  const n = Math.hypot(p[o + 3], p[o + 4], p[o + 5], p[o + 6]) || 1;
  p[o + 3] /= n; p[o + 4] /= n; p[o + 5] /= n; p[o + 6] /= n;
}
export function poseMatrix(out, p, o) {
  return M.fromRTS(out, p[o + 3], p[o + 4], p[o + 5], p[o + 6], p[o], p[o + 1], p[o + 2], 1);
}
export function poseDistanceMm(a, ao, b, bo) {
  return 1000 * Math.hypot(a[ao] - b[bo], a[ao + 1] - b[bo + 1], a[ao + 2] - b[bo + 2]);
}

// glam's lerp and slerp, as the stepper's timeline interpolates the wrist.
export function interpolatePose(out, a, ao, b, bo, f) {
  for (let k = 0; k < 3; k++) out[k] = a[ao + k] + (b[bo + k] - a[ao + k]) * f;
  let bx = b[bo + 3], by = b[bo + 4], bz = b[bo + 5], bw = b[bo + 6];
  const ax = a[ao + 3], ay = a[ao + 4], az = a[ao + 5], aw = a[ao + 6];
  let dot = ax * bx + ay * by + az * bz + aw * bw;
  if (dot < 0) { bx = -bx; by = -by; bz = -bz; bw = -bw; dot = -dot; }
  let s0, s1;
  if (dot > 1 - Number.EPSILON) {
    s0 = 1 - f; s1 = f;
  } else {
    const th = Math.acos(dot), sn = Math.sin(th);
    s0 = Math.sin(th * (1 - f)) / sn; s1 = Math.sin(th * f) / sn;
  }
  out[3] = ax * s0 + bx * s1; out[4] = ay * s0 + by * s1; out[5] = az * s0 + bz * s1; out[6] = aw * s0 + bw * s1;
  normalizeQuat(out, 0);
}

// ---------------------------------------------------------------- orbit camera
// A camera that orbits `target` at `dist` (`yaw` about y, `pitch` above the horizon, radians),
// turned by dragging on `canvas` and brought nearer or farther by its wheel. Returns its state,
// which the page may set too (`target`, `dist`).
export function orbitCamera(canvas, { yaw, pitch, dist, target }) {
  const orbit = { yaw, pitch, dist, target, dragging: false, lx: 0, ly: 0 };
  canvas.addEventListener('pointerdown', (e) => {
    orbit.dragging = true; orbit.lx = e.clientX; orbit.ly = e.clientY;
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener('pointermove', (e) => {
    if (!orbit.dragging) return;
    orbit.yaw -= (e.clientX - orbit.lx) * 0.008;
    orbit.pitch = Math.min(1.5, Math.max(-1.2, orbit.pitch + (e.clientY - orbit.ly) * 0.008));
    orbit.lx = e.clientX; orbit.ly = e.clientY;
  });
  const endDrag = () => { orbit.dragging = false; };
  canvas.addEventListener('pointerup', endDrag);
  canvas.addEventListener('pointercancel', endDrag);
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    orbit.dist = Math.min(10, Math.max(0.15, orbit.dist * Math.exp(e.deltaY * 0.001)));
  }, { passive: false });
  return orbit;
}

// Aims `orbit` at the middle of the box lo..hi, near enough that the box fills the view.
export function frameBox(orbit, lo, hi) {
  orbit.target = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
  const extent = 0.5 * Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) + 0.12;
  orbit.dist = Math.min(3, Math.max(0.45, extent / 0.4));
}

// out = the orbit's view-projection for a view `aspect` wide (55 degrees high); `view` and
// `proj` get its two parts.
export function orbitViewProj(orbit, aspect, view, proj, out) {
  const cp = Math.cos(orbit.pitch), tg = orbit.target;
  const eye = [tg[0] + orbit.dist * cp * Math.sin(orbit.yaw), tg[1] + orbit.dist * Math.sin(orbit.pitch),
    tg[2] + orbit.dist * cp * Math.cos(orbit.yaw)];
  M.lookAt(view, eye, tg, [0, 1, 0]);
  M.perspective(proj, 55 * Math.PI / 180, aspect, 0.02, 50);
  return M.multiply(out, proj, view);
}
