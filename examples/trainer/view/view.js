// examples/trainer/view/view.js: the page of a run (view_html.hpp). Plain WebGL 2, no libraries.
// Reads the JSON header (#smg-header) and the base64 block (#smg-data) that smg_trainer embeds,
// draws the node graph over time, and exposes a small test hook, window.__smgView.
(function () {
  'use strict';
  const head = JSON.parse(document.getElementById('smg-header').textContent);
  const T = head.T, N = head.N, K = head.K;

  // --- data -------------------------------------------------------------------------------------
  const raw = atob(document.getElementById('smg-data').textContent.trim());
  const bytes = new Uint8Array(raw.length);
  for (let i = 0; i < raw.length; ++i) bytes[i] = raw.charCodeAt(i);
  const kinds = { u8: Uint8Array, u16: Uint16Array, f32: Float32Array };
  function array(name) {
    const a = head.arrays[name];
    if (!a) return null;
    const Type = kinds[a.type];
    return new Type(bytes.buffer, a.offset, a.bytes / Type.BYTES_PER_ELEMENT);
  }
  // Quantised positions back to metres: x = lo + q * step per axis (view_html.hpp).
  function dequantise(q) {
    if (!q) return null;
    const lo = head.quant.lo, step = head.quant.step, out = new Float32Array(q.length);
    for (let i = 0; i < q.length; ++i) out[i] = lo[i % 3] + q[i] * step[i % 3];
    return out;
  }
  const nodes = dequantise(array('nodes'));                 // [T][N][3]
  const conf = array('confidence');                         // [T][N] c * 255
  const visible = array('visible');                         // [T][N]
  const classes = array('classes');                         // [N], 255 = none
  const graph = array('graph');                             // [N][K], 65535 = none
  const cut = array('cut_edges');                           // [E][2]
  const gStatic = dequantise(array('gaussians_static'));    // [S][3]
  const gStaticRgb = array('gaussians_static_rgb');
  const gDynamic = dequantise(array('gaussians_dynamic'));  // [T][D][3]
  const gDynamicRgb = array('gaussians_dynamic_rgb');
  const queries = dequantise(array('queries'));             // [M][T][3]
  const queryError = array('query_error');                  // [M][T] metres
  const S = gStatic ? gStatic.length / 3 : 0;
  const D = gDynamic ? gDynamic.length / (3 * T) : 0;
  const M = queries ? queries.length / (3 * T) : 0;

  const edges = [];  // kept graph edges, each once
  for (let i = 0; i < N; ++i)
    for (let k = 0; k < K; ++k) {
      const j = graph[i * K + k];
      if (j === 65535) continue;
      let listed = false;
      if (j < i) for (let m = 0; m < K; ++m) if (graph[j * K + m] === i) listed = true;
      if (!listed) edges.push(i, j);
    }

  // --- colours ----------------------------------------------------------------------------------
  // Viridis at 9 stops, linearly interpolated: the confidence scale (dark = distrusted).
  const viridis = [[68, 1, 84], [71, 44, 122], [59, 81, 139], [44, 113, 142], [33, 144, 141],
                   [39, 173, 129], [92, 200, 99], [170, 220, 50], [253, 231, 37]];
  function scale(v) {
    const x = Math.min(Math.max(v, 0), 1) * (viridis.length - 1), i = Math.min(Math.floor(x), viridis.length - 2);
    const f = x - i, a = viridis[i], b = viridis[i + 1];
    return [0, 1, 2].map((c) => (a[c] + f * (b[c] - a[c])) / 255);
  }
  const palette = [[0.55, 0.55, 0.6], [0.45, 0.6, 0.9], [0.95, 0.45, 0.3], [0.95, 0.8, 0.25], [0.4, 0.85, 0.45],
                   [0.8, 0.45, 0.9], [0.3, 0.85, 0.85], [0.95, 0.55, 0.75], [0.7, 0.7, 0.35], [0.55, 0.4, 0.3]];
  const classColour = (c) => (c === 255 ? [0.5, 0.5, 0.5] : palette[c % palette.length]);

  // --- WebGL ------------------------------------------------------------------------------------
  const canvas = document.getElementById('gl');
  const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
  if (!gl) {
    document.getElementById('hint').textContent = 'this page needs WebGL 2';
    return;
  }
  const vs = `#version 300 es
  in vec3 a_pos; in vec3 a_col;
  uniform mat4 u_mvp; uniform float u_size;
  out vec3 v_col;
  void main() { gl_Position = u_mvp * vec4(a_pos, 1.0); gl_PointSize = u_size; v_col = a_col; }`;
  const fs = `#version 300 es
  precision mediump float;
  in vec3 v_col; uniform float u_round; uniform float u_alpha;
  out vec4 o;
  void main() {
    if (u_round > 0.5 && length(gl_PointCoord - vec2(0.5)) > 0.5) discard;
    o = vec4(v_col, u_alpha);
  }`;
  function shader(type, src) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, vs));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  gl.useProgram(prog);
  const loc = { pos: gl.getAttribLocation(prog, 'a_pos'), col: gl.getAttribLocation(prog, 'a_col'),
                mvp: gl.getUniformLocation(prog, 'u_mvp'), size: gl.getUniformLocation(prog, 'u_size'),
                round: gl.getUniformLocation(prog, 'u_round'), alpha: gl.getUniformLocation(prog, 'u_alpha') };
  gl.enable(gl.DEPTH_TEST);
  gl.enable(gl.BLEND);
  gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);

  function buffer(data, usage) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, usage || gl.STATIC_DRAW);
    return b;
  }
  // Binds positions (and per-vertex colours, or one colour for all) for the next draw.
  function bind(posBuf, colBuf, colour) {
    gl.bindBuffer(gl.ARRAY_BUFFER, posBuf);
    gl.enableVertexAttribArray(loc.pos);
    gl.vertexAttribPointer(loc.pos, 3, gl.FLOAT, false, 0, 0);
    if (colBuf) {
      gl.bindBuffer(gl.ARRAY_BUFFER, colBuf);
      gl.enableVertexAttribArray(loc.col);
      gl.vertexAttribPointer(loc.col, 3, gl.FLOAT, false, 0, 0);
    } else {
      gl.disableVertexAttribArray(loc.col);
      gl.vertexAttrib3f(loc.col, colour[0], colour[1], colour[2]);
    }
  }
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const nodeBuf = buffer(new Float32Array(N * 3), gl.DYNAMIC_DRAW);
  const nodeColBuf = buffer(new Float32Array(N * 3), gl.DYNAMIC_DRAW);
  const edgeIdx = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, edgeIdx);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint16Array(edges), gl.STATIC_DRAW);
  const cutIdx = gl.createBuffer();
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, cutIdx);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, cut ? new Uint16Array(cut) : new Uint16Array(0), gl.STATIC_DRAW);
  // Colours as floats: three-byte vertex formats are converted on every draw by some drivers.
  const unit = (rgb) => Float32Array.from(rgb, (v) => v / 255);
  const staticBuf = S ? buffer(gStatic) : null;
  const staticColBuf = S ? buffer(unit(gStaticRgb)) : null;
  const dynamicBuf = D ? buffer(new Float32Array(D * 3), gl.DYNAMIC_DRAW) : null;
  const dynamicColBuf = D ? buffer(unit(gDynamicRgb)) : null;
  const TRAIL = Math.min(12, T);
  const lineBuf = buffer(new Float32Array(6), gl.DYNAMIC_DRAW);
  const lineColBuf = buffer(new Float32Array(6), gl.DYNAMIC_DRAW);

  // --- the view: orbit about a target, "up" from the first training camera ----------------------
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => mul(a, 1 / (Math.hypot(a[0], a[1], a[2]) || 1));
  const cam0 = head.train_cameras[0];
  const up = cam0 ? norm([-cam0.R[3], -cam0.R[4], -cam0.R[5]]) : [0, 0, 1];
  const e1 = norm(cross(up, Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0])), e2 = cross(up, e1);
  let centre = [0, 0, 0];
  for (let i = 0; i < N; ++i) centre = add(centre, [nodes[i * 3], nodes[i * 3 + 1], nodes[i * 3 + 2]]);
  centre = mul(centre, 1 / Math.max(N, 1));
  const extent = head.extent > 0 ? head.extent : 1;
  const view = { target: centre, yaw: 0.6, pitch: 0.4, dist: 2 * extent };
  if (cam0) {  // start where the training camera stands
    const d = sub(cam0.c, centre), h = [dot(d, e1), dot(d, e2), dot(d, up)];
    view.dist = 1.5 * Math.max(Math.hypot(h[0], h[1], h[2]), 0.2 * extent);  // a step back: the cameras in view
    view.yaw = Math.atan2(h[1], h[0]);
    view.pitch = Math.asin(Math.min(Math.max(h[2] / view.dist, -0.99), 0.99));
  }
  function eye() {
    const c = Math.cos(view.pitch);
    const dir = add(add(mul(e1, c * Math.cos(view.yaw)), mul(e2, c * Math.sin(view.yaw))), mul(up, Math.sin(view.pitch)));
    return add(view.target, mul(dir, view.dist));
  }
  // Column-major 4x4 projection * view.
  function mvp() {
    const w = canvas.width, h = canvas.height, e = eye();
    const f = norm(sub(view.target, e)), s = norm(cross(f, up)), u = cross(s, f);
    const near = view.dist * 0.01, far = view.dist * 20 + extent * 10, fy = 1 / Math.tan(0.5 * 0.8);
    const fx = fy * h / w, A = (far + near) / (near - far), B = 2 * far * near / (near - far);
    const V = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0, -dot(s, e), -dot(u, e), dot(f, e), 1];
    const P = [fx, 0, 0, 0, 0, fy, 0, 0, 0, 0, A, -1, 0, 0, B, 0];
    const out = new Float32Array(16);
    for (let c = 0; c < 4; ++c)
      for (let r = 0; r < 4; ++r) {
        let v = 0;
        for (let k = 0; k < 4; ++k) v += P[k * 4 + r] * V[c * 4 + k];
        out[c * 4 + r] = v;
      }
    return out;
  }

  // --- state and drawing ------------------------------------------------------------------------
  const ui = (id) => document.getElementById(id);
  const state = { t: 0, playing: false, selected: -1 };
  const slider = ui('time');
  slider.max = String(T - 1);

  function nodeColours(t) {
    const out = new Float32Array(N * 3), byClass = ui('colour-by').value === 'class';
    for (let i = 0; i < N; ++i) {
      let c = byClass ? classColour(classes[i]) : scale(conf[t * N + i] / 255);
      if (state.selected >= 0 && i !== state.selected && !neighbours(state.selected).includes(i)) c = mul(c, 0.35);
      out.set(c, i * 3);
    }
    return out;
  }
  function neighbours(i) {
    const out = [];
    for (let k = 0; k < K; ++k) if (graph[i * K + k] !== 65535) out.push(graph[i * K + k]);
    return out;
  }
  // Line segments [2 S][3] with per-vertex colours, uploaded anew (trails, tracks, frusta).
  function lines(segs, cols) {
    gl.bindBuffer(gl.ARRAY_BUFFER, lineBuf);
    gl.bufferData(gl.ARRAY_BUFFER, segs, gl.DYNAMIC_DRAW);
    gl.bindBuffer(gl.ARRAY_BUFFER, lineColBuf);
    gl.bufferData(gl.ARRAY_BUFFER, cols, gl.DYNAMIC_DRAW);
    bind(lineBuf, lineColBuf);
    gl.drawArrays(gl.LINES, 0, segs.length / 3);
  }
  // Four rays and the image rectangle of a camera, `depth` metres deep.
  function frustum(c, depth, colour, segs, cols) {
    const corner = (u, v) => {
      const d = [(u - c.pp[0]) / c.f[0] * depth, (v - c.pp[1]) / c.f[1] * depth, depth];
      const R = c.R;  // world-to-camera rows: world = R^T d + centre
      return add(c.c, [R[0] * d[0] + R[3] * d[1] + R[6] * d[2], R[1] * d[0] + R[4] * d[1] + R[7] * d[2],
                       R[2] * d[0] + R[5] * d[1] + R[8] * d[2]]);
    };
    const k = [corner(0, 0), corner(c.size[0], 0), corner(c.size[0], c.size[1]), corner(0, c.size[1])];
    for (let i = 0; i < 4; ++i) {
      segs.push(...c.c, ...k[i], ...k[i], ...k[(i + 1) % 4]);
      for (let r = 0; r < 4; ++r) cols.push(...colour);
    }
  }

  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(0.05, 0.055, 0.07, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.uniformMatrix4fv(loc.mvp, false, mvp());
    gl.uniform1f(loc.alpha, 1);
    gl.uniform1f(loc.round, 0);  // square points and lines (gl_PointCoord means nothing on a line)
    const t = state.t, dpi = dpr;

    if (ui('show-gaussians').checked) {
      gl.uniform1f(loc.size, Math.max(1, Math.round(2 * dpi)));
      gl.disable(gl.BLEND);  // opaque squares: software rasterisers draw them several times faster
      if (S) { bind(staticBuf, staticColBuf); gl.drawArrays(gl.POINTS, 0, S); }
      if (D) {
        gl.bindBuffer(gl.ARRAY_BUFFER, dynamicBuf);
        gl.bufferSubData(gl.ARRAY_BUFFER, 0, gDynamic.subarray(t * D * 3, (t + 1) * D * 3));
        bind(dynamicBuf, dynamicColBuf);
        gl.drawArrays(gl.POINTS, 0, D);
      }
      gl.enable(gl.BLEND);
    }
    gl.bindBuffer(gl.ARRAY_BUFFER, nodeBuf);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, nodes.subarray(t * N * 3, (t + 1) * N * 3));
    gl.bindBuffer(gl.ARRAY_BUFFER, nodeColBuf);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, nodeColours(t));
    if (ui('show-edges').checked && edges.length) {
      bind(nodeBuf, null, [0.75, 0.78, 0.85]);
      gl.uniform1f(loc.alpha, state.selected >= 0 ? 0.12 : 0.35);
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, edgeIdx);
      gl.drawElements(gl.LINES, edges.length, gl.UNSIGNED_SHORT, 0);
      gl.uniform1f(loc.alpha, 1);
    }
    if (ui('show-cut').checked && cut && cut.length) {
      bind(nodeBuf, null, [1.0, 0.3, 0.25]);
      gl.uniform1f(loc.alpha, 0.6);
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, cutIdx);
      gl.drawElements(gl.LINES, cut.length, gl.UNSIGNED_SHORT, 0);
      gl.uniform1f(loc.alpha, 1);
    }
    if (ui('show-trails').checked && t > 0) {  // the last TRAIL frames, fading out
      const n = Math.min(TRAIL, t), segs = new Float32Array(N * n * 6), cols = new Float32Array(N * n * 6);
      const base = nodeColours(t);
      let o = 0;
      for (let i = 0; i < N; ++i)
        for (let s = 0; s < n; ++s) {
          const a = (t - s - 1) * N * 3 + i * 3, b = (t - s) * N * 3 + i * 3;
          segs.set(nodes.subarray(a, a + 3), o);
          segs.set(nodes.subarray(b, b + 3), o + 3);
          const fa = 1 - (s + 1) / (n + 1), fb = 1 - s / (n + 1);
          for (let c = 0; c < 3; ++c) { cols[o + c] = base[i * 3 + c] * fa; cols[o + 3 + c] = base[i * 3 + c] * fb; }
          o += 6;
        }
      lines(segs, cols);
    }
    if (M && ui('show-queries').checked && t > 0) {  // query tracks up to t, coloured by error if known
      const segs = new Float32Array(M * t * 6), cols = new Float32Array(M * t * 6);
      let o = 0;
      for (let m = 0; m < M; ++m)
        for (let s = 0; s < t; ++s) {
          const a = (m * T + s) * 3;
          segs.set(queries.subarray(a, a + 6), o);
          const c = queryError ? scale(1 - Math.min(queryError[m * T + s + 1] / (0.1 * extent), 1)) : [1, 1, 1];
          cols.set(c, o);
          cols.set(c, o + 3);
          o += 6;
        }
      lines(segs, cols);
    }
    if (ui('show-cameras').checked) {
      const segs = [], cols = [], depth = 0.05 * extent;
      head.train_cameras.forEach((c, i) => { if (i === t) frustum(c, depth, [1, 0.85, 0.3], segs, cols); });
      head.test_cameras.forEach((c) => frustum(c, depth, [0.4, 0.75, 1], segs, cols));
      if (segs.length) lines(new Float32Array(segs), new Float32Array(cols));
    }
    if (state.selected >= 0) {  // the selected node's edges, bright
      const i = state.selected, segs = [], cols = [];
      for (const j of neighbours(i)) {
        segs.push(...nodes.subarray((t * N + i) * 3, (t * N + i) * 3 + 3), ...nodes.subarray((t * N + j) * 3, (t * N + j) * 3 + 3));
        cols.push(1, 1, 1, 1, 1, 1);
      }
      if (segs.length) lines(new Float32Array(segs), new Float32Array(cols));
    }
    gl.uniform1f(loc.round, 1);
    gl.uniform1f(loc.size, 7 * dpi);
    bind(nodeBuf, nodeColBuf);
    gl.drawArrays(gl.POINTS, 0, N);
    if (state.selected >= 0) {
      gl.uniform1f(loc.size, 13 * dpi);
      bind(nodeBuf, null, [1, 1, 1]);
      gl.drawArrays(gl.POINTS, state.selected, 1);
    }
  }

  // --- header, legend, images, node panel -------------------------------------------------------
  const metrics = head.metrics || {};
  const fmt = (v) => (typeof v === 'number' ? (Number.isInteger(v) ? String(v) : v.toPrecision(4)) : String(v));
  ui('title').textContent = 'smg_trainer · ' + (metrics.variant || head.variant) + ' · ' +
                            (head.source === 'procedural' ? 'procedural scene ' + (metrics.scene || '') +
                             ' seed ' + fmt(metrics.seed) : head.source);
  const summaryKeys = [['T', 'frames'], ['nodes', 'nodes'], ['edges', 'edges'], ['gate_removed_edges', 'gate cut'],
                       ['gaussians', 'Gaussians'], ['test_psnr', 'test PSNR'], ['test_psnr_masked', 'test mPSNR'],
                       ['mpsnr', 'mPSNR'], ['mssim', 'mSSIM'],
                       ['epe', head.has_truth ? 'node EPE (m)' : 'query EPE (m)'], ['delta_5', 'δ5%'],
                       ['alpha', 'α'], ['seconds_total', 'seconds']];
  ui('summary').innerHTML = '';
  for (const [key, label] of summaryKeys)
    if (key in metrics) {
      const s = document.createElement('span');
      s.innerHTML = label + ' <b></b>';
      s.querySelector('b').textContent = fmt(metrics[key]);
      ui('summary').appendChild(s);
    }
  for (const [key, value] of Object.entries(metrics)) {
    const tr = document.createElement('tr');
    tr.innerHTML = '<td></td><td></td>';
    tr.children[0].textContent = key;
    tr.children[1].textContent = typeof value === 'object' ? JSON.stringify(value) : fmt(value);
    ui('metrics').appendChild(tr);
  }
  function legend() {
    const el = ui('legend');
    if (ui('colour-by').value === 'class') {
      const used = new Set(classes);
      el.innerHTML = '<div>semantic class</div>';
      for (const c of [...used].sort((a, b) => a - b)) {
        const row = document.createElement('div'), col = classColour(c).map((v) => Math.round(v * 255));
        row.innerHTML = '<span class="swatch"></span><span></span>';
        row.children[0].style.background = 'rgb(' + col.join(',') + ')';
        row.children[1].textContent = c === 255 ? 'none' : (head.class_names[c] || 'class ' + c);
        el.appendChild(row);
      }
    } else {
      const stops = viridis.map((c, i) => 'rgb(' + c.join(',') + ') ' + (100 * i / (viridis.length - 1)) + '%');
      el.innerHTML = '<div>confidence c<sub>t</sub> (E6)</div><div class="bar"></div>' +
                     '<div class="ticks"><span>0</span><span>0.5</span><span>1</span></div>';
      el.querySelector('.bar').style.background = 'linear-gradient(to right,' + stops.join(',') + ')';
    }
  }
  const urls = {};
  function url(name) {  // an embedded image as a blob: URL (made once)
    if (!name) return null;
    if (!urls[name]) {
      const a = head.arrays[name];
      urls[name] = URL.createObjectURL(new Blob([bytes.subarray(a.offset, a.offset + a.bytes)], { type: a.mime }));
    }
    return urls[name];
  }
  const frameImages = {};  // per frame, the images panel's elements (made once: no decoding again)
  function images() {
    const el = ui('images');
    if (!frameImages[state.t]) {
      const list = [];
      for (const p of head.pictures) {
        if (p.frame !== state.t) continue;
        const div = document.createElement('div');
        div.className = 'picture';
        div.innerHTML = '<div class="label"></div><div class="row"></div>';
        div.children[0].textContent = p.label + (p.score !== undefined ? ' · ' + p.score_name + ' ' + p.score.toFixed(2) + ' dB' : '');
        for (const [name, title] of [[p.truth, 'image'], [p.render, 'render'], [p.mask, 'covisible mask']]) {
          if (!name) continue;
          const img = document.createElement('img');
          img.src = url(name);
          img.title = title;
          img.alt = title;
          div.children[1].appendChild(img);
        }
        list.push(div);
      }
      frameImages[state.t] = list;
    }
    el.replaceChildren(...frameImages[state.t]);
  }
  function nodePanel() {
    const i = state.selected, panel = ui('node-panel');
    panel.hidden = i < 0;
    if (i < 0) return;
    ui('node-title').textContent = 'node ' + i + (classes[i] !== 255 ? ' (' + (head.class_names[classes[i]] || classes[i]) + ')' : '') +
                                   ': ' + neighbours(i).length + ' neighbours · c(t) at frame ' + state.t + ' = ' +
                                   (conf[state.t * N + i] / 255).toFixed(3);
    const c2 = ui('node-plot').getContext('2d'), w = c2.canvas.width, h = c2.canvas.height;
    c2.clearRect(0, 0, w, h);
    const x = (t) => 8 + (w - 16) * (T > 1 ? t / (T - 1) : 0), y = (v) => h - 10 - (h - 20) * v;
    c2.strokeStyle = '#333';
    c2.strokeRect(8, 10, w - 16, h - 20);
    for (let t = 0; t < T; ++t) if (!visible[t * N + i]) { c2.fillStyle = '#402020'; c2.fillRect(x(t) - 2, 10, 4, h - 20); }
    c2.strokeStyle = '#fde725';
    c2.beginPath();
    for (let t = 0; t < T; ++t) c2[t ? 'lineTo' : 'moveTo'](x(t), y(conf[t * N + i] / 255));
    c2.stroke();
    c2.strokeStyle = '#fff';
    c2.beginPath();
    c2.moveTo(x(state.t), 10);
    c2.lineTo(x(state.t), h - 10);
    c2.stroke();
    c2.fillStyle = '#888';
    c2.fillText('1', 0, 12);
    c2.fillText('0', 0, h - 8);
  }

  function setFrame(t) {
    state.t = Math.max(0, Math.min(T - 1, t | 0));
    slider.value = String(state.t);
    ui('frame-label').textContent = 'frame ' + state.t + ' / ' + (T - 1);
    images();
    nodePanel();
    draw();
  }
  slider.addEventListener('input', () => setFrame(+slider.value));
  ui('colour-by').addEventListener('change', () => { legend(); draw(); });
  for (const id of ['show-edges', 'show-cut', 'show-trails', 'show-gaussians', 'show-cameras', 'show-queries'])
    ui(id).addEventListener('change', draw);
  if (!cut || !cut.length) ui('show-cut').parentElement.hidden = true;
  if (!M) ui('show-queries').parentElement.hidden = true;
  if (!S && !D) ui('show-gaussians').parentElement.hidden = true;
  let last = 0;
  function tick(now) {
    if (!state.playing) return;
    if (now - last > 125) { last = now; setFrame((state.t + 1) % T); }
    requestAnimationFrame(tick);
  }
  ui('play').addEventListener('click', () => {
    state.playing = !state.playing;
    ui('play').textContent = state.playing ? 'pause' : 'play';
    if (state.playing) requestAnimationFrame(tick);
  });

  // Orbit (drag), pan (right or shift drag), zoom (wheel), pick (click).
  let drag = null;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('mousedown', (e) => { drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey, moved: false }; });
  window.addEventListener('mouseup', (e) => {
    if (drag && !drag.moved && e.target === canvas) pick(e);
    drag = null;
  });
  window.addEventListener('mousemove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (drag.pan) {
      const f = norm(sub(view.target, eye())), s = norm(cross(f, up)), u = cross(s, f), k = view.dist * 0.0015;
      view.target = add(view.target, add(mul(s, -dx * k), mul(u, dy * k)));
    } else {
      view.yaw -= dx * 0.008;
      view.pitch = Math.max(-1.5, Math.min(1.5, view.pitch + dy * 0.008));
    }
    draw();
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    view.dist *= Math.exp(e.deltaY * 0.001);
    draw();
  }, { passive: false });
  function project(p, m) {
    const x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12], y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13];
    const w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
    return w > 0 ? [(x / w * 0.5 + 0.5) * canvas.clientWidth, (0.5 - y / w * 0.5) * canvas.clientHeight] : null;
  }
  function pick(e) {
    const r = canvas.getBoundingClientRect(), m = mvp();
    let best = -1, bestD = 10;
    for (let i = 0; i < N; ++i) {
      const q = project(nodes.subarray((state.t * N + i) * 3, (state.t * N + i) * 3 + 3), m);
      if (!q) continue;
      const d = Math.hypot(q[0] - (e.clientX - r.left), q[1] - (e.clientY - r.top));
      if (d < bestD) { bestD = d; best = i; }
    }
    state.selected = best;
    nodePanel();
    draw();
  }
  window.addEventListener('resize', draw);

  // --- test hook (tests/pipeline/test_view_html.py) ---------------------------------------------
  // Draws `frames` frames back to back with requestAnimationFrame and resolves to the mean frames
  // per second: mode 'time' advances the frame index every frame (as play does, images panel
  // included), 'orbit' turns the view (the 3D drawing alone).
  function measureFps(frames, mode) {
    return new Promise((resolve) => {
      let n = 0, start = 0;
      function step(now) {
        if (n === 0) start = now;
        if (mode === 'orbit') { view.yaw += 0.02; draw(); } else setFrame((state.t + 1) % T);
        gl.finish();
        if (++n > frames) { resolve(1000 * frames / (now - start)); return; }
        requestAnimationFrame(step);
      }
      requestAnimationFrame(step);
    });
  }
  // Pixel statistics of the drawn canvas: how many pixels differ from the background, and a hash.
  function pixels() {
    draw();
    const w = canvas.width, h = canvas.height, px = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let lit = 0, hash = 0;
    for (let i = 0; i < px.length; i += 4) {
      if (Math.abs(px[i] - 13) + Math.abs(px[i + 1] - 14) + Math.abs(px[i + 2] - 18) > 12) ++lit;
      hash = (hash * 31 + px[i] + 7 * px[i + 1] + 13 * px[i + 2]) >>> 0;
    }
    return { width: w, height: h, lit: lit, hash: hash };
  }
  window.__smgView = {
    header: head, frameCount: T, nodeCount: N, setFrame: setFrame, frame: () => state.t,
    nodesAt: (t) => Array.from(nodes.subarray(t * N * 3, (t + 1) * N * 3)),
    confidenceAt: (t) => Array.from(conf.subarray(t * N, (t + 1) * N), (v) => v / 255),
    select: (i) => { state.selected = i; nodePanel(); draw(); },
    setColour: (by) => { ui('colour-by').value = by; legend(); draw(); },
    show: (id, on) => { ui('show-' + id).checked = on; draw(); },
    orbit: (dyaw, dpitch, zoom) => { view.yaw += dyaw; view.pitch += dpitch; view.dist *= zoom || 1; draw(); },
    pixels: pixels, measureFps: measureFps, counts: { edges: edges.length / 2, cut: cut ? cut.length / 2 : 0, S: S, D: D, M: M },
    ready: true
  };
  legend();
  setFrame(0);
})();
