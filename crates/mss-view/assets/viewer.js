// mss view: the page. A small WebGL2 renderer (shaded triangles, lines),
// an orbit camera, CPU ray picking, and the WebSocket protocol of
// crates/mss-view/src/protocol.rs. No third-party code.
"use strict";

(function () {
  const TOPOLOGY_TAG = 0x4d535401;
  const FRAME_TAG = 0x4d535402;
  const token = new URLSearchParams(location.search).get("token") || "";
  const $ = (id) => document.getElementById(id);
  const canvas = $("view");
  const gl = canvas.getContext("webgl2", { antialias: false, preserveDrawingBuffer: false });

  // State visible to tests and tools.
  const api = {
    ready: false, connected: false, framesReceived: 0, framesDrawn: 0, framesShown: 0,
    scene: null, status: null, error: null, surface: 0, colour: "displacement",
  };
  window.mssView = api;

  function showMessage(text, info) {
    const m = $("message");
    if (!text) { m.hidden = true; return; }
    m.textContent = text;
    m.className = info ? "info" : "";
    m.hidden = false;
  }
  if (!gl) { showMessage("This browser has no WebGL2: the viewer cannot draw."); api.error = "no WebGL2"; return; }

  // ---- small vector helpers -------------------------------------------
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => Math.sqrt(dot(a, a));
  const unit = (a) => { const n = norm(a) || 1; return scale(a, 1 / n); };

  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  }
  function lookAt(eye, target, up) {
    const z = unit(sub(eye, target)), x = unit(cross(up, z)), y = cross(z, x);
    return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
      -dot(x, eye), -dot(y, eye), -dot(z, eye), 1];
  }
  function mul(a, b) { // column-major 4x4
    const o = new Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s;
    }
    return o;
  }

  // ---- shaders ---------------------------------------------------------
  const MESH_VS = `#version 300 es
  in vec3 position; in vec3 normal; in float value;
  uniform mat4 viewProj; out vec3 vPos; out vec3 vNormal; out float vValue;
  void main() { vPos = position; vNormal = normal; vValue = value; gl_Position = viewProj * vec4(position, 1.0); }`;
  const MESH_FS = `#version 300 es
  precision highp float;
  in vec3 vPos; in vec3 vNormal; in float vValue;
  uniform vec3 eye; uniform vec2 range; uniform int mode; uniform int flat_shading; uniform int has_value;
  out vec4 colour;
  vec3 sequential(float t) { // perceptually ordered, dark blue to yellow
    t = clamp(t, 0.0, 1.0);
    vec3 c0 = vec3(0.267, 0.005, 0.329), c1 = vec3(0.128, 0.567, 0.551), c2 = vec3(0.993, 0.906, 0.144);
    return t < 0.5 ? mix(c0, c1, t * 2.0) : mix(c1, c2, t * 2.0 - 1.0);
  }
  vec3 diverging(float t) { // blue (compressed) to white to red (expanded)
    t = clamp(t, 0.0, 1.0);
    vec3 lo = vec3(0.23, 0.30, 0.75), mid = vec3(0.92, 0.92, 0.92), hi = vec3(0.71, 0.02, 0.15);
    return t < 0.5 ? mix(lo, mid, t * 2.0) : mix(mid, hi, t * 2.0 - 1.0);
  }
  void main() {
    vec3 n = flat_shading == 1 ? normalize(cross(dFdx(vPos), dFdy(vPos))) : normalize(vNormal);
    vec3 v = normalize(eye - vPos);
    if (dot(n, v) < 0.0) n = -n;
    float t = (vValue - range.x) / max(range.y - range.x, 1e-30);
    vec3 base = has_value == 0 ? vec3(0.6) : (mode == 0 ? sequential(t) : diverging(t));
    float diffuse = max(dot(n, v), 0.0);
    float sky = 0.5 + 0.5 * n.z;
    vec3 c = base * (0.25 + 0.15 * sky + 0.65 * diffuse) + vec3(0.12) * pow(diffuse, 24.0);
    colour = vec4(c, 1.0);
  }`;
  const LINE_VS = `#version 300 es
  in vec3 position; uniform mat4 viewProj; uniform vec3 offset;
  void main() { gl_Position = viewProj * vec4(position + offset, 1.0); }`;
  const LINE_FS = `#version 300 es
  precision mediump float; uniform vec4 colour; out vec4 outColour;
  void main() { outColour = colour; }`;

  function program(vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src); gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }
  const meshProgram = program(MESH_VS, MESH_FS);
  const lineProgram = program(LINE_VS, LINE_FS);
  const loc = (p, n) => gl.getUniformLocation(p, n);

  // ---- scene data ------------------------------------------------------
  let surfaces = [];      // {info, triangles: Uint32Array, positions, values..., vao, buffers}
  let lines = [];          // {vao, count, colour, offsetIndex}
  let pokeLines = null;
  let generation = -1;
  let target = [0, 0, 0], distance = 1, yaw = -0.7, pitch = 0.45;
  let displayRange = { displacement: 0, jacobian: 0.01 };

  function makeSurface(info, triangles) {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const pos = gl.createBuffer(), nrm = gl.createBuffer(), val = gl.createBuffer(), idx = gl.createBuffer();
    const attrs = [[pos, "position", 3], [nrm, "normal", 3], [val, "value", 1]];
    for (const [b, name, size] of attrs) {
      const l = gl.getAttribLocation(meshProgram, name);
      gl.bindBuffer(gl.ARRAY_BUFFER, b);
      gl.bufferData(gl.ARRAY_BUFFER, info.vertices * size * 4, gl.DYNAMIC_DRAW);
      gl.enableVertexAttribArray(l);
      gl.vertexAttribPointer(l, size, gl.FLOAT, false, 0, 0);
    }
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, idx);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, triangles, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    return { info, triangles, vao, pos, nrm, val, positions: null, displacement: null, jacobian: null,
      normals: new Float32Array(info.vertices * 3) };
  }

  function lineBuffer(points) {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(points), gl.STATIC_DRAW);
    const l = gl.getAttribLocation(lineProgram, "position");
    gl.enableVertexAttribArray(l);
    gl.vertexAttribPointer(l, 3, gl.FLOAT, false, 0, 0);
    gl.bindVertexArray(null);
    return { vao, count: points.length / 3 };
  }

  function circle(out, c, u, v, r, n) {
    for (let i = 0; i < n; i++) {
      const a0 = (i / n) * 2 * Math.PI, a1 = ((i + 1) / n) * 2 * Math.PI;
      out.push(...add(c, add(scale(u, r * Math.cos(a0)), scale(v, r * Math.sin(a0)))));
      out.push(...add(c, add(scale(u, r * Math.cos(a1)), scale(v, r * Math.sin(a1)))));
    }
  }
  function sphereLines(c, r) {
    const out = [];
    for (let k = -2; k <= 2; k++) { // latitude circles
      const z = (k / 3) * r, rr = Math.sqrt(r * r - z * z);
      circle(out, add(c, [0, 0, z]), [1, 0, 0], [0, 1, 0], rr, 32);
    }
    for (let k = 0; k < 4; k++) { // meridians
      const a = (k / 4) * Math.PI;
      circle(out, c, [Math.cos(a), Math.sin(a), 0], [0, 0, 1], r, 32);
    }
    return out;
  }
  function boxLines(lo, hi) {
    const out = [], c = (i) => [i & 1 ? hi[0] : lo[0], i & 2 ? hi[1] : lo[1], i & 4 ? hi[2] : lo[2]];
    for (let i = 0; i < 8; i++) for (const bit of [1, 2, 4]) if (!(i & bit)) out.push(...c(i), ...c(i | bit));
    return out;
  }
  function gridLines(point, normal, size, n) {
    const nn = unit(normal);
    const u = unit(Math.abs(nn[2]) < 0.9 ? cross(nn, [0, 0, 1]) : cross(nn, [1, 0, 0])), v = cross(nn, u);
    const out = [];
    for (let i = -n; i <= n; i++) {
      const s = (i / n) * size;
      out.push(...add(point, add(scale(u, s), scale(v, -size))), ...add(point, add(scale(u, s), scale(v, size))));
      out.push(...add(point, add(scale(v, s), scale(u, -size))), ...add(point, add(scale(v, s), scale(u, size))));
    }
    return out;
  }
  function capsuleLines(a, b, r) {
    const axis = unit(sub(b, a));
    const u = unit(Math.abs(axis[2]) < 0.9 ? cross(axis, [0, 0, 1]) : cross(axis, [1, 0, 0])), v = cross(axis, u);
    const out = [];
    circle(out, a, u, v, r, 24); circle(out, b, u, v, r, 24);
    for (let k = 0; k < 4; k++) {
      const d = add(scale(u, r * Math.cos(k * Math.PI / 2)), scale(v, r * Math.sin(k * Math.PI / 2)));
      out.push(...add(a, d), ...add(b, d));
    }
    return out.concat(sphereLines(a, r), sphereLines(b, r));
  }

  function setupScene(info) {
    api.scene = info; generation = info.generation; api.ready = false;
    surfaces = []; lines = []; pokeLines = null;
    displayRange = { displacement: 0, jacobian: 0.01 };
    grab = null;
    if (info.error) {
      showMessage(`${info.name}:\n${info.error}` + (info.mode === "live" ? "\n\nFix the scene and press Reset." : ""));
      api.error = info.error;
    } else {
      showMessage(null); api.error = null;
    }
    const [lo, hi] = info.bounds;
    target = scale(add(lo, hi), 0.5);
    const diag = Math.max(norm(sub(hi, lo)), 1e-6);
    distance = 1.6 * diag;
    const size = Math.max(diag, 1e-6);
    let hasGround = false;
    info.obstacles.forEach((o, i) => {
      let pts;
      if (o.kind === "plane") {
        pts = gridLines(o.point.map((c, k) => (Math.abs(o.normal[2]) > 0.99 && k < 2 ? target[k] : c)), o.normal, size, 10);
        if (o.normal[2] > 0.99) hasGround = true;
      } else if (o.kind === "sphere") pts = sphereLines(o.centre, o.radius);
      else if (o.kind === "box" || o.kind === "mesh") pts = boxLines(o.min, o.max);
      else if (o.kind === "capsule") pts = capsuleLines(o.a, o.b, o.radius);
      if (pts) lines.push({ ...lineBuffer(pts), colour: [0.75, 0.78, 0.85, 1], obstacle: i });
    });
    if (!hasGround && info.nodes > 0) { // a reference grid under the body
      lines.push({ ...lineBuffer(gridLines([target[0], target[1], lo[2]], [0, 0, 1], size, 10)), colour: [0.4, 0.43, 0.5, 1], obstacle: -1 });
    }
    if (info.poke_radius > 0) pokeLines = lineBuffer(sphereLines([0, 0, 0], info.poke_radius));
    const sel = $("surface");
    sel.innerHTML = "";
    info.surfaces.forEach((s, i) => {
      const o = document.createElement("option");
      o.value = i; o.textContent = s.name === "surface" ? "embedded surface" : "lattice skin";
      sel.appendChild(o);
    });
    api.surface = Math.min(api.surface, Math.max(info.surfaces.length - 1, 0));
    sel.value = api.surface;
    const replay = info.mode === "replay";
    $("replay").hidden = !replay;
    $("tools").hidden = replay;
    if (replay) {
      $("frame").max = Math.max(info.frame_times.length - 1, 0);
    }
  }

  function setupTopology(view) {
    const dv = new DataView(view);
    const n = dv.getUint32(4, true);
    let at = 8;
    for (let s = 0; s < n && api.scene; s++) {
      const t = dv.getUint32(at, true); at += 4;
      const tris = new Uint32Array(view.slice(at, at + 12 * t)); at += 12 * t;
      surfaces.push(makeSurface(api.scene.surfaces[s], tris));
    }
  }

  function computeNormals(s) {
    const p = s.positions, t = s.triangles, out = s.normals;
    out.fill(0);
    for (let i = 0; i < t.length; i += 3) {
      const a = 3 * t[i], b = 3 * t[i + 1], c = 3 * t[i + 2];
      const ux = p[b] - p[a], uy = p[b + 1] - p[a + 1], uz = p[b + 2] - p[a + 2];
      const vx = p[c] - p[a], vy = p[c + 1] - p[a + 1], vz = p[c + 2] - p[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const k of [a, b, c]) { out[k] += nx; out[k + 1] += ny; out[k + 2] += nz; }
    }
  }

  function readFrame(view) {
    const dv = new DataView(view);
    const n = dv.getUint32(4, true);
    const gen = Number(dv.getBigUint64(8, true));
    if (gen !== generation) return;
    let at = 32;
    for (let s = 0; s < n && s < surfaces.length; s++) {
      const v = dv.getUint32(at, true); at += 4;
      const surf = surfaces[s];
      surf.positions = new Float32Array(view, at, 3 * v); at += 12 * v;
      surf.displacement = new Float32Array(view, at, v); at += 4 * v;
      surf.jacobian = new Float32Array(view, at, v); at += 4 * v;
      if (surf.info.name === "surface") computeNormals(surf);
      gl.bindBuffer(gl.ARRAY_BUFFER, surf.pos); gl.bufferSubData(gl.ARRAY_BUFFER, 0, surf.positions);
      gl.bindBuffer(gl.ARRAY_BUFFER, surf.nrm); gl.bufferSubData(gl.ARRAY_BUFFER, 0, surf.normals);
    }
    api.framesReceived++;
    api.ready = true;
    freshFrame = true;
    uploadValues();
    dirty = true;
  }

  function uploadValues() {
    const s = surfaces[api.surface];
    if (!s || !s.positions) return;
    const values = api.colour === "displacement" ? s.displacement : s.jacobian;
    let m = 0;
    if (api.colour === "displacement") { for (const x of values) m = Math.max(m, x); displayRange.displacement = Math.max(displayRange.displacement, m); }
    else { for (const x of values) m = Math.max(m, Math.abs(x - 1)); displayRange.jacobian = Math.max(displayRange.jacobian, m); }
    gl.bindBuffer(gl.ARRAY_BUFFER, s.val); gl.bufferSubData(gl.ARRAY_BUFFER, 0, values);
    drawLegend(s);
  }

  function formatLength(m) {
    const a = Math.abs(m);
    if (a === 0) return "0 mm";
    if (a < 1e-3) return (m * 1e6).toPrecision(3) + " \u00b5m";
    if (a < 1) return (m * 1e3).toPrecision(3) + " mm";
    return m.toPrecision(3) + " m";
  }
  function valueRange() {
    return api.colour === "displacement" ? [0, Math.max(displayRange.displacement, 1e-12)]
      : [1 - displayRange.jacobian, 1 + displayRange.jacobian];
  }
  let legendKey = "";
  function drawLegend(s) {
    const [lo0, hi0] = valueRange();
    const key = `${api.colour} ${lo0.toPrecision(3)} ${hi0.toPrecision(3)} ${s && s.info.has_jacobian}`;
    if (key === legendKey) return;
    legendKey = key;
    const c = $("legend-bar"), g = c.getContext("2d");
    const grad = g.createLinearGradient(0, c.height, 0, 0);
    const stops = api.colour === "displacement"
      ? [[0, "#440154"], [0.5, "#21918c"], [1, "#fde725"]] : [[0, "#3b4cc0"], [0.5, "#ebebeb"], [1, "#b40426"]];
    for (const [t, col] of stops) grad.addColorStop(t, col);
    g.fillStyle = grad; g.fillRect(0, 0, c.width, c.height);
    const [lo, hi] = valueRange();
    const hasJ = s && s.info.has_jacobian;
    if (api.colour === "displacement") {
      $("legend-title").textContent = "|u|"; $("legend-max").textContent = formatLength(hi); $("legend-min").textContent = formatLength(lo);
    } else {
      $("legend-title").textContent = hasJ ? "J = V/V0" : "J n/a";
      $("legend-max").textContent = hi.toFixed(4); $("legend-min").textContent = lo.toFixed(4);
    }
  }

  // ---- camera and drawing ---------------------------------------------
  let dirty = true, freshFrame = false, viewProj = null, eye = [0, 0, 1];
  function camera() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    eye = add(target, scale([Math.cos(pitch) * Math.cos(yaw), Math.cos(pitch) * Math.sin(yaw), Math.sin(pitch)], distance));
    viewProj = mul(perspective(0.7, w / Math.max(h, 1), distance * 0.01, distance * 20), lookAt(eye, target, [0, 0, 1]));
  }

  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; dirty = true; }
    if (!dirty) return;
    dirty = false;
    camera();
    gl.viewport(0, 0, w, h);
    gl.clearColor(0.125, 0.141, 0.169, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    const s = surfaces[api.surface];
    if (s && s.positions) {
      gl.useProgram(meshProgram);
      gl.uniformMatrix4fv(loc(meshProgram, "viewProj"), false, viewProj);
      gl.uniform3fv(loc(meshProgram, "eye"), eye);
      gl.uniform2fv(loc(meshProgram, "range"), valueRange());
      gl.uniform1i(loc(meshProgram, "mode"), api.colour === "displacement" ? 0 : 1);
      gl.uniform1i(loc(meshProgram, "flat_shading"), s.info.name === "skin" ? 1 : 0);
      gl.uniform1i(loc(meshProgram, "has_value"), api.colour === "jacobian" && !s.info.has_jacobian ? 0 : 1);
      gl.bindVertexArray(s.vao);
      gl.drawElements(gl.TRIANGLES, s.triangles.length, gl.UNSIGNED_INT, 0);
      gl.bindVertexArray(null);
    }
    gl.useProgram(lineProgram);
    gl.uniformMatrix4fv(loc(lineProgram, "viewProj"), false, viewProj);
    const offsets = (api.status && api.status.obstacle_offsets) || [];
    for (const l of lines) {
      gl.uniform4fv(loc(lineProgram, "colour"), l.colour);
      gl.uniform3fv(loc(lineProgram, "offset"), (l.obstacle >= 0 && offsets[l.obstacle]) || [0, 0, 0]);
      gl.bindVertexArray(l.vao); gl.drawArrays(gl.LINES, 0, l.count);
    }
    if (pokeLines && api.status && api.status.poke_centre) {
      gl.uniform4fv(loc(lineProgram, "colour"), [1.0, 0.6, 0.2, 1]);
      gl.uniform3fv(loc(lineProgram, "offset"), api.status.poke_centre);
      gl.bindVertexArray(pokeLines.vao); gl.drawArrays(gl.LINES, 0, pokeLines.count);
    }
    gl.bindVertexArray(null);
    api.framesDrawn++;
    // Frames of the simulation that reached the screen.
    if (freshFrame) { api.framesShown++; freshFrame = false; }
  }

  function loop() { draw(); requestAnimationFrame(loop); }
  requestAnimationFrame(loop);
  window.addEventListener("resize", () => { dirty = true; });

  // ---- rays and picking -----------------------------------------------
  function rayAt(cx, cy) {
    camera();
    const r = canvas.getBoundingClientRect();
    const x = ((cx - r.left) / r.width) * 2 - 1, y = 1 - ((cy - r.top) / r.height) * 2;
    const fwd = unit(sub(target, eye)), right = unit(cross(fwd, [0, 0, 1])), up = cross(right, fwd);
    const t = Math.tan(0.35), aspect = r.width / Math.max(r.height, 1);
    return { origin: eye, dir: unit(add(fwd, add(scale(right, x * t * aspect), scale(up, y * t)))), fwd };
  }
  function pick(ray) {
    const s = surfaces[api.surface];
    if (!s || !s.positions) return null;
    const p = s.positions, tris = s.triangles, o = ray.origin, d = ray.dir;
    let best = null;
    for (let i = 0; i < tris.length; i += 3) {
      const a = 3 * tris[i], b = 3 * tris[i + 1], c = 3 * tris[i + 2];
      const e1 = [p[b] - p[a], p[b + 1] - p[a + 1], p[b + 2] - p[a + 2]];
      const e2 = [p[c] - p[a], p[c + 1] - p[a + 1], p[c + 2] - p[a + 2]];
      const h = cross(d, e2), det = dot(e1, h);
      if (Math.abs(det) < 1e-20) continue;
      const f = 1 / det, sv = [o[0] - p[a], o[1] - p[a + 1], o[2] - p[a + 2]];
      const u = f * dot(sv, h);
      if (u < 0 || u > 1) continue;
      const q = cross(sv, e1), v = f * dot(d, q);
      if (v < 0 || u + v > 1) continue;
      const t = f * dot(e2, q);
      if (t > 0 && (!best || t < best.t)) best = { t, triangle: i / 3, normal: unit(cross(e1, e2)) };
    }
    if (!best) return null;
    best.point = add(o, scale(d, best.t));
    if (dot(best.normal, d) > 0) best.normal = scale(best.normal, -1);
    return best;
  }
  function onPlane(ray, point, normal) {
    const den = dot(ray.dir, normal);
    if (Math.abs(den) < 1e-9) return null;
    return add(ray.origin, scale(ray.dir, dot(sub(point, ray.origin), normal) / den));
  }
  // Screen position (CSS pixels) of a world point, for tests and tools.
  api.project = function (p) {
    camera();
    const m = viewProj, x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12];
    const y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13], w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
    const r = canvas.getBoundingClientRect();
    return [r.left + (x / w + 1) / 2 * r.width, r.top + (1 - y / w) / 2 * r.height];
  };
  // A screen point where the body is under the cursor, nearest the
  // projected centre of the body (null if none is visible).
  api.findBodyPixel = function () {
    const c = api.project(target);
    for (let radius = 0; radius < 400; radius += 8) {
      for (let k = 0; k < Math.max(1, radius); k++) {
        const a = (k / Math.max(1, radius)) * 2 * Math.PI;
        const x = c[0] + radius * Math.cos(a), y = c[1] + radius * Math.sin(a);
        const hit = pick(rayAt(x, y));
        if (hit) return { x, y, point: hit.point };
      }
    }
    return null;
  };
  api.camera = () => ({ eye, target, distance, yaw, pitch });
  // The fraction of the canvas in saturated colour (the body's colour
  // map; background, grid and text are grey), read right after a draw.
  api.colouredFraction = function () {
    dirty = true; draw();
    const w = canvas.width, h = canvas.height, px = new Uint8Array(4 * w * h);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let n = 0;
    for (let i = 0; i < px.length; i += 4) {
      const mx = Math.max(px[i], px[i + 1], px[i + 2]), mn = Math.min(px[i], px[i + 1], px[i + 2]);
      if (mx - mn > 40) n++;
    }
    return n / (w * h);
  };

  // ---- input -----------------------------------------------------------
  let ws = null, grab = null, orbit = null, pendingDrag = null;
  const send = (m) => { if (ws && ws.readyState === 1) ws.send(JSON.stringify(m)); };
  api.send = send;
  function tool() { return document.querySelector("input[name=tool]:checked").value; }

  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    const ray = rayAt(e.clientX, e.clientY);
    const live = api.scene && api.scene.mode === "live" && !api.scene.error;
    const hit = e.button === 0 && !e.shiftKey && live ? pick(ray) : null;
    if (hit && tool() === "drag") {
      grab = { kind: "drag", plane: hit.point, normal: ray.fwd };
      send({ type: "pick", surface: api.surface, triangle: hit.triangle, point: hit.point });
    } else if (hit && tool() === "poke") {
      const r = api.scene.poke_radius;
      const centre = add(hit.point, scale(hit.normal, r * 1.02));
      grab = { kind: "poke", plane: centre, normal: ray.fwd };
      send({ type: "poke", centre });
    } else {
      orbit = { x: e.clientX, y: e.clientY, pan: e.button !== 0 || e.shiftKey };
    }
  });
  canvas.addEventListener("pointermove", (e) => {
    if (grab) {
      const p = onPlane(rayAt(e.clientX, e.clientY), grab.plane, grab.normal);
      if (p) pendingDrag = grab.kind === "drag" ? { type: "drag", target: p } : { type: "poke", centre: p };
    } else if (orbit) {
      const dx = e.clientX - orbit.x, dy = e.clientY - orbit.y;
      orbit.x = e.clientX; orbit.y = e.clientY;
      if (orbit.pan) {
        const fwd = unit(sub(target, eye)), right = unit(cross(fwd, [0, 0, 1])), up = cross(right, fwd);
        const k = distance * 0.0015;
        target = add(target, add(scale(right, -dx * k), scale(up, dy * k)));
      } else {
        yaw -= dx * 0.008;
        pitch = Math.max(-1.5, Math.min(1.5, pitch + dy * 0.008));
      }
      dirty = true;
    }
  });
  function endPointer() {
    if (grab && grab.kind === "drag") { pendingDrag = null; send({ type: "release" }); }
    else if (grab && pendingDrag) { send(pendingDrag); pendingDrag = null; }
    grab = null; orbit = null;
  }
  canvas.addEventListener("pointerup", endPointer);
  canvas.addEventListener("pointercancel", endPointer);
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    distance *= Math.exp(e.deltaY * 0.001);
    dirty = true;
  }, { passive: false });
  // At most one drag message per displayed frame.
  setInterval(() => { if (pendingDrag) { send(pendingDrag); pendingDrag = null; } }, 16);

  $("play").onclick = () => send({ type: api.status && api.status.playing ? "pause" : "play" });
  $("step").onclick = () => send({ type: "step" });
  $("reset").onclick = () => send({ type: "reset" });
  $("unpoke").onclick = () => send({ type: "unpoke" });
  $("scale").oninput = () => {
    const v = Math.pow(10, Number($("scale").value));
    $("scale-value").textContent = v.toFixed(2) + "x";
    send({ type: "time_scale", value: v });
  };
  $("surface").onchange = () => { api.surface = Number($("surface").value); uploadValues(); dirty = true; };
  $("colour").onchange = () => { api.colour = $("colour").value; uploadValues(); dirty = true; };
  $("frame").oninput = () => send({ type: "seek", frame: Number($("frame").value) });
  window.addEventListener("keydown", (e) => {
    if (e.target.tagName === "INPUT" && e.target.type !== "radio") return;
    if (e.key === " ") { e.preventDefault(); $("play").click(); }
    else if (e.key === "s") send({ type: "step" });
    else if (e.key === "r") send({ type: "reset" });
    else if (e.key === "p") {
      const next = tool() === "poke" ? "drag" : "poke";
      document.querySelector(`input[name=tool][value=${next}]`).checked = true;
    }
  });

  let hudText = "";
  function hud(st) {
    const sc = api.scene;
    const lines = [];
    lines.push(`${sc.mode === "replay" ? "replay" : "live"}: ${sc.name}`);
    lines.push(`cells ${sc.cells}  nodes ${sc.nodes}  h ${formatLength(sc.cell_size)}`);
    lines.push(`t = ${st.time.toFixed(3)} s  ${st.playing ? "running" : "paused"}`);
    if (sc.mode === "live") {
      lines.push(`frame ${st.frame_ms.toFixed(1)} ms CPU  sub-steps ${st.substeps}`);
    } else {
      lines.push(`frame ${st.frame + 1} / ${sc.frame_times.length}`);
    }
    lines.push(`real-time factor ${st.real_time_factor.toFixed(2)} (asked ${st.time_scale.toFixed(2)})`);
    lines.push(`max |u| ${formatLength(st.max_displacement)}`);
    const text = lines.join("\n");
    if (text !== hudText) { hudText = text; $("hud").textContent = text; }
    const label = st.playing ? "Pause" : "Play";
    if ($("play").textContent !== label) $("play").textContent = label;
    if (sc.mode === "replay") {
      $("frame").value = st.frame;
      $("frame-value").textContent = `t = ${(sc.frame_times[st.frame] || 0).toFixed(3)} s`;
    }
  }

  // ---- connection --------------------------------------------------------
  function connect() {
    showMessage(api.scene ? null : "connecting\u2026", true);
    const scheme = location.protocol === "https:" ? "wss" : "ws";
    ws = new WebSocket(`${scheme}://${location.host}/ws?token=${encodeURIComponent(token)}`);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => { api.connected = true; if (!api.scene) showMessage("building the scene\u2026", true); };
    ws.onmessage = (e) => {
      if (typeof e.data === "string") {
        const m = JSON.parse(e.data);
        if (m.type === "scene") { setupScene(m); dirty = true; }
        else if (m.type === "status") {
          if (m.generation !== generation) return;
          api.status = m;
          if (api.scene) hud(m);
          if (m.error) showMessage(m.error); else if (!api.scene.error) showMessage(null);
          dirty = true;
        }
      } else {
        const tag = new DataView(e.data).getUint32(0, true);
        if (tag === TOPOLOGY_TAG) setupTopology(e.data);
        else if (tag === FRAME_TAG) readFrame(e.data);
      }
    };
    ws.onclose = () => {
      api.connected = false;
      showMessage("the connection to mss view was lost; retrying\u2026", true);
      setTimeout(connect, 1000);
    };
  }
  connect();
})();
