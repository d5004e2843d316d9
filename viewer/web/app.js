// deog view: draws the map's tiles as they arrive over the WebSocket, the
// robots, their beams, estimates and paths, on one canvas redrawn every
// animation frame (robots glide between updates).
'use strict';

const PALETTE = ['#2b6cb0', '#c05621', '#2f855a', '#9b2c9b', '#b7791f', '#2c7a7b', '#c53030', '#4c51bf'];
const UNKNOWN = 255;
const LOST_SCORE = 0.5;

const canvas = document.getElementById('map');
const ctx = canvas.getContext('2d');
const mapSelect = document.getElementById('maps');
const robotRows = document.querySelector('#robots tbody');

// Grey levels of the cell shades: 0 occupied (near black) to 250 free
// (white); unknown cells stay transparent over the background.
const SHADE_RGBA = new Uint8ClampedArray(256 * 4);
for (let s = 0; s < 256; s++) {
  const level = Math.round(30 + (s / 250) * 225);
  SHADE_RGBA.set(s === UNKNOWN ? [0, 0, 0, 0] : [level, level, Math.min(255, level + 10), 255], s * 4);
}

const view = {
  map: null,          // {name, resolution_m, tile_size}
  maps: [],
  tiles: new Map(),   // "x,y" -> {x, y, canvas, seenAt}
  bounds: null,       // tile-key bounds {minX, minY, maxX, maxY}
  robots: new Map(),  // name -> robot
  colors: new Map(),
  center: { x: 0, y: 0 },
  scale: 40,          // pixels per metre
  userMoved: false,
  socket: null,
};

const stats = { frames: [], drawMs: [], tileMessages: 0, robotMessages: 0 };

function colorOf(name) {
  if (!view.colors.has(name)) view.colors.set(name, PALETTE[view.colors.size % PALETTE.length]);
  return view.colors.get(name);
}

// ---- the connection -------------------------------------------------------

function connect() {
  const params = new URLSearchParams(location.search);
  const url = new URL('/ws', location.href);
  url.protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
  if (params.get('map')) url.searchParams.set('map', params.get('map'));
  const socket = new WebSocket(url);
  socket.binaryType = 'arraybuffer';
  view.socket = socket;
  socket.onopen = () => setConnection(true);
  socket.onclose = () => {
    setConnection(false);
    setTimeout(connect, 1000);
  };
  socket.onmessage = (event) => {
    if (typeof event.data === 'string') onMessage(JSON.parse(event.data));
    else onTile(event.data);
  };
}

function setConnection(on) {
  const badge = document.getElementById('connection');
  badge.textContent = on ? 'live' : 'reconnecting…';
  badge.className = on ? 'on' : 'off';
}

function onMessage(message) {
  switch (message.type) {
    case 'hello':
      view.maps = message.maps;
      showMapList(message.map);
      break;
    case 'maps':
      view.maps = message.maps;
      showMapList(view.map ? view.map.name : null);
      break;
    case 'map':
      view.map = { name: message.name, resolution_m: message.resolution_m, tile_size: message.tile_size };
      view.tiles.clear();
      view.bounds = null;
      showMapList(message.name);
      break;
    case 'cleared':
      view.tiles.clear();
      view.bounds = null;
      break;
    case 'robots':
      stats.robotMessages++;
      for (const data of message.robots) onRobot(data, message.history);
      showRobots();
      break;
    case 'kidnap':
      onKidnap(message);
      break;
    case 'particles': {
      const robot = view.robots.get(message.robot);
      if (robot) robot.particles = message;
      break;
    }
  }
}

function onTile(buffer) {
  const bytes = new DataView(buffer);
  if (bytes.getUint8(0) !== 1 || !view.map) return;
  const x = bytes.getInt32(1, true);
  const y = bytes.getInt32(5, true);
  const side = bytes.getUint16(9, true);
  const shades = new Uint8Array(buffer, 11, side * side);
  const key = x + ',' + y;
  let tile = view.tiles.get(key);
  if (!tile) {
    const c = document.createElement('canvas');
    c.width = side;
    c.height = side;
    tile = { x, y, canvas: c, seenAt: 0 };
    view.tiles.set(key, tile);
    const b = view.bounds;
    view.bounds = b
      ? { minX: Math.min(b.minX, x), minY: Math.min(b.minY, y), maxX: Math.max(b.maxX, x), maxY: Math.max(b.maxY, y) }
      : { minX: x, minY: y, maxX: x, maxY: y };
  }
  const image = new ImageData(side, side);
  for (let i = 0; i < shades.length; i++) image.data.set(SHADE_RGBA.subarray(shades[i] * 4, shades[i] * 4 + 4), i * 4);
  tile.canvas.getContext('2d').putImageData(image, 0, 0);
  tile.seenAt = Date.now();
  stats.tileMessages++;
}

function onRobot(data, history) {
  let robot = view.robots.get(data.name);
  if (!robot) {
    robot = { name: data.name, truePath: [], estimatePath: [], kidnaps: [], shown: null, shownEstimate: null };
    view.robots.set(data.name, robot);
  }
  robot.data = data;
  if (history) {
    robot.truePath = data.true_path || [];
    robot.estimatePath = data.estimate_path || [];
    robot.kidnaps = data.kidnaps || [];
  } else {
    const t = data.true_pose;
    if (t) extendPath(robot.truePath, [t[0], t[1]]);
    const e = data.estimate;
    if (e) extendPath(robot.estimatePath, [e.pose[0], e.pose[1], e.converged ? 1 : 0]);
  }
}

function extendPath(path, point) {
  const last = path[path.length - 1];
  if (last && Math.hypot(last[0] - point[0], last[1] - point[1]) < 0.02 && last[2] === point[2]) return;
  path.push(point);
  if (path.length > 4000) path.splice(0, path.length - 4000);
}

function onKidnap(message) {
  const robot = view.robots.get(message.robot);
  if (robot) robot.kidnaps.push(message);
}

function showMapList(selected) {
  mapSelect.replaceChildren(...view.maps.map((m) => {
    const option = document.createElement('option');
    option.value = m.name;
    option.textContent = m.name;
    option.selected = m.name === selected;
    return option;
  }));
  const shown = view.maps.find((m) => m.name === selected);
  document.getElementById('map-facts').textContent = shown
    ? `${shown.cells.toLocaleString()} cells observed in ${shown.tiles} tiles · version ${shown.version}`
    : 'no map yet';
}

mapSelect.addEventListener('change', () => {
  const map = mapSelect.value;
  const params = new URLSearchParams(location.search);
  params.set('map', map);
  history.replaceState(null, '', '?' + params.toString());
  view.userMoved = false;
  if (view.socket && view.socket.readyState === WebSocket.OPEN) {
    view.socket.send(JSON.stringify({ type: 'show', map }));
  }
});

function stateOf(robot) {
  const e = robot.data.estimate;
  if (!e) return 'none';
  if (e.lost_score >= LOST_SCORE) return 'lost';
  return e.converged ? 'converged' : 'searching';
}

function showRobots() {
  const rows = [];
  for (const robot of [...view.robots.values()].sort((a, b) => a.name.localeCompare(b.name))) {
    const state = stateOf(robot);
    const e = robot.data.estimate;
    const error = robot.data.error;
    const tr = document.createElement('tr');
    tr.dataset.robot = robot.name;
    tr.innerHTML =
      `<td><span class="dot" style="background:${colorOf(robot.name)}"></span>${escapeHtml(robot.name)}</td>` +
      `<td class="state-${state}">${state === 'none' ? '—' : state}</td>` +
      `<td class="${error && error.m > 0.5 ? 'error-far' : ''}">${error ? errorText(error) : '—'}</td>` +
      `<td>${e ? e.particles.toLocaleString() : '—'}</td>`;
    rows.push(tr);
  }
  robotRows.replaceChildren(...rows);
}

function errorText(error) {
  const distance = error.m < 1 ? `${(error.m * 100).toFixed(1)} cm` : `${error.m.toFixed(2)} m`;
  return `${distance} ${error.deg.toFixed(1)}°`;
}

function escapeHtml(text) {
  return text.replace(/[&<>"']/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;', "'": '&#39;' })[c]);
}

// ---- pan and zoom -----------------------------------------------------------

function toScreen(x, y) {
  return [canvas.width / 2 + (x - view.center.x) * view.scale, canvas.height / 2 - (y - view.center.y) * view.scale];
}

function toWorld(px, py) {
  return [view.center.x + (px - canvas.width / 2) / view.scale, view.center.y - (py - canvas.height / 2) / view.scale];
}

function fit() {
  let box = null;
  if (view.bounds && view.map) {
    const span = view.map.tile_size * view.map.resolution_m;
    box = { minX: view.bounds.minX * span, minY: view.bounds.minY * span, maxX: (view.bounds.maxX + 1) * span, maxY: (view.bounds.maxY + 1) * span };
  }
  for (const robot of view.robots.values()) {
    const p = robot.data.true_pose || (robot.data.estimate && robot.data.estimate.pose);
    if (!p) continue;
    box = box
      ? { minX: Math.min(box.minX, p[0]), minY: Math.min(box.minY, p[1]), maxX: Math.max(box.maxX, p[0]), maxY: Math.max(box.maxY, p[1]) }
      : { minX: p[0] - 2, minY: p[1] - 2, maxX: p[0] + 2, maxY: p[1] + 2 };
  }
  if (!box) return;
  view.center = { x: (box.minX + box.maxX) / 2, y: (box.minY + box.maxY) / 2 };
  const w = Math.max(box.maxX - box.minX, 1);
  const h = Math.max(box.maxY - box.minY, 1);
  view.scale = Math.max(2, Math.min(400, 0.92 * Math.min(canvas.width / w, canvas.height / h)));
}

let drag = null;
canvas.addEventListener('mousedown', (e) => {
  drag = { x: e.offsetX, y: e.offsetY, center: { ...view.center } };
  canvas.classList.add('dragging');
});
window.addEventListener('mouseup', () => {
  drag = null;
  canvas.classList.remove('dragging');
});
canvas.addEventListener('mousemove', (e) => {
  if (!drag) return;
  const ratio = window.devicePixelRatio || 1;
  view.center = {
    x: drag.center.x - ((e.offsetX - drag.x) * ratio) / view.scale,
    y: drag.center.y + ((e.offsetY - drag.y) * ratio) / view.scale,
  };
  view.userMoved = true;
});
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  const ratio = window.devicePixelRatio || 1;
  const [wx, wy] = toWorld(e.offsetX * ratio, e.offsetY * ratio);
  view.scale = Math.max(2, Math.min(2000, view.scale * Math.exp(-e.deltaY * 0.0015)));
  const [nx, ny] = toWorld(e.offsetX * ratio, e.offsetY * ratio);
  view.center.x += wx - nx;
  view.center.y += wy - ny;
  view.userMoved = true;
}, { passive: false });
canvas.addEventListener('dblclick', () => {
  view.userMoved = false;
  fit();
});
window.addEventListener('keydown', (e) => {
  if (e.key === 'f' || e.key === 'F') {
    view.userMoved = false;
    fit();
  }
});

// ---- drawing -----------------------------------------------------------------

function resize() {
  const ratio = window.devicePixelRatio || 1;
  const w = Math.round(canvas.clientWidth * ratio);
  const h = Math.round(canvas.clientHeight * ratio);
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
}

// Eases a shown pose towards the newest one; a jump (a kidnap, a first
// fix) is taken at once.
function glide(shown, target, dt) {
  if (!target) return null;
  if (!shown || Math.hypot(shown[0] - target[0], shown[1] - target[1]) > 1) return target.slice();
  const k = Math.min(1, dt * 15);
  let dTheta = target[2] - shown[2];
  dTheta = Math.atan2(Math.sin(dTheta), Math.cos(dTheta));
  return [shown[0] + (target[0] - shown[0]) * k, shown[1] + (target[1] - shown[1]) * k, shown[2] + dTheta * k];
}

function drawTiles() {
  if (!view.map) return;
  const span = view.map.tile_size * view.map.resolution_m;
  ctx.save();
  ctx.imageSmoothingEnabled = false;
  // World to screen with y up; a tile's row 0 is its lowest cells.
  ctx.setTransform(view.scale, 0, 0, -view.scale, canvas.width / 2 - view.center.x * view.scale, canvas.height / 2 + view.center.y * view.scale);
  const [x0, y1] = toWorld(0, 0);
  const [x1, y0] = toWorld(canvas.width, canvas.height);
  for (const tile of view.tiles.values()) {
    const wx = tile.x * span;
    const wy = tile.y * span;
    if (wx > x1 || wx + span < x0 || wy > y1 || wy + span < y0) continue;
    ctx.drawImage(tile.canvas, wx, wy, span, span);
  }
  ctx.restore();
}

function drawPaths(robot, color) {
  ctx.lineWidth = 1.5;
  ctx.strokeStyle = color;
  ctx.globalAlpha = 0.55;
  ctx.setLineDash([]);
  strokeRuns(robot.truePath, () => true);
  // Estimates: joined only while converged; before that, faint dots.
  ctx.globalAlpha = 0.9;
  ctx.setLineDash([5, 3]);
  strokeRuns(robot.estimatePath, (p) => p[2] === 1);
  ctx.setLineDash([]);
  ctx.globalAlpha = 0.3;
  ctx.fillStyle = color;
  for (const p of robot.estimatePath) {
    if (p[2] === 1) continue;
    const [sx, sy] = toScreen(p[0], p[1]);
    ctx.fillRect(sx - 1.5, sy - 1.5, 3, 3);
  }
  ctx.globalAlpha = 1;
}

// Strokes the path's runs of kept points; a jump of more than a metre
// (a kidnap, a re-localization) breaks the line.
function strokeRuns(path, keep) {
  ctx.beginPath();
  let joined = false;
  let last = null;
  for (const p of path) {
    if (!keep(p)) {
      joined = false;
      continue;
    }
    const [sx, sy] = toScreen(p[0], p[1]);
    if (joined && last && Math.hypot(p[0] - last[0], p[1] - last[1]) <= 1) ctx.lineTo(sx, sy);
    else ctx.moveTo(sx, sy);
    joined = true;
    last = p;
  }
  ctx.stroke();
}

function drawBeams(robot, color) {
  const beams = robot.data.beams || [];
  ctx.strokeStyle = color;
  ctx.fillStyle = color;
  for (const [x, y, angle, range, half, echo] of beams) {
    const [sx, sy] = toScreen(x, y);
    const r = range * view.scale;
    ctx.globalAlpha = echo ? 0.16 : 0.05;
    if (half > 0) {
      ctx.beginPath();
      ctx.moveTo(sx, sy);
      ctx.arc(sx, sy, r, -angle - half, -angle + half);
      ctx.closePath();
      ctx.fill();
      if (echo) {
        ctx.globalAlpha = 0.7;
        ctx.beginPath();
        ctx.arc(sx, sy, r, -angle - half, -angle + half);
        ctx.stroke();
      }
    } else {
      ctx.globalAlpha = echo ? 0.35 : 0.08;
      ctx.beginPath();
      ctx.moveTo(sx, sy);
      ctx.lineTo(sx + r * Math.cos(angle), sy - r * Math.sin(angle));
      ctx.stroke();
    }
  }
  ctx.globalAlpha = 1;
}

function drawKidnaps(robot) {
  ctx.strokeStyle = '#333';
  ctx.lineWidth = 1.5;
  for (const k of robot.kidnaps) {
    const [fx, fy] = toScreen(k.from[0], k.from[1]);
    const [tx, ty] = toScreen(k.to[0], k.to[1]);
    ctx.setLineDash([4, 4]);
    ctx.beginPath();
    ctx.moveTo(fx, fy);
    ctx.lineTo(tx, ty);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.beginPath();
    ctx.moveTo(fx - 6, fy - 6); ctx.lineTo(fx + 6, fy + 6);
    ctx.moveTo(fx + 6, fy - 6); ctx.lineTo(fx - 6, fy + 6);
    ctx.stroke();
    ctx.beginPath();
    ctx.arc(tx, ty, 7, 0, 2 * Math.PI);
    ctx.stroke();
  }
}

// A sample of the localizer's particles: small dots in the robot's
// colour, while the sample is of the shown map and at most 2 s older
// than the estimate.
function drawParticles(robot, color) {
  const sample = robot.particles;
  const e = robot.data.estimate;
  if (!sample || !view.map || sample.map !== view.map.name) return;
  if (e && e.time_s - sample.time_s > 2) return;
  ctx.fillStyle = color;
  ctx.globalAlpha = 0.55;
  for (const [x, y] of sample.poses) {
    const [sx, sy] = toScreen(x, y);
    ctx.fillRect(sx - 1.5, sy - 1.5, 3, 3);
  }
  ctx.globalAlpha = 1;
}

// An explorer's goal: a diamond in its colour, a dashed line from the
// robot to it.
function drawGoal(robot, color) {
  const goal = robot.data.goal;
  if (!goal || !view.map || goal.map !== view.map.name) return;
  const [gx, gy] = toScreen(goal.x, goal.y);
  const from = robot.shown || robot.shownEstimate;
  ctx.strokeStyle = color;
  ctx.lineWidth = 1.5;
  if (from) {
    const [sx, sy] = toScreen(from[0], from[1]);
    ctx.globalAlpha = 0.6;
    ctx.setLineDash([2, 4]);
    ctx.beginPath();
    ctx.moveTo(sx, sy);
    ctx.lineTo(gx, gy);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.globalAlpha = 1;
  }
  ctx.fillStyle = color;
  ctx.beginPath();
  ctx.moveTo(gx, gy - 7); ctx.lineTo(gx + 6, gy); ctx.lineTo(gx, gy + 7); ctx.lineTo(gx - 6, gy);
  ctx.closePath();
  ctx.fill();
  ctx.strokeStyle = '#fff';
  ctx.stroke();
}

function drawRobot(robot, color, dt) {
  const radius = Math.max(4, (robot.data.radius || 0.2) * view.scale);
  robot.shown = glide(robot.shown, robot.data.true_pose, dt);
  if (robot.shown) {
    const [sx, sy] = toScreen(robot.shown[0], robot.shown[1]);
    ctx.fillStyle = color;
    ctx.beginPath();
    ctx.arc(sx, sy, radius, 0, 2 * Math.PI);
    ctx.fill();
    ctx.strokeStyle = '#fff';
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(sx, sy);
    ctx.lineTo(sx + radius * Math.cos(robot.shown[2]), sy - radius * Math.sin(robot.shown[2]));
    ctx.stroke();
    robot.marker = [sx, sy];
  }
  const e = robot.data.estimate;
  robot.shownEstimate = glide(robot.shownEstimate, e && e.pose, dt);
  if (e && robot.shownEstimate) {
    const state = stateOf(robot);
    const ring = state === 'lost' ? '#d00030' : state === 'converged' ? color : '#dd8800';
    const [sx, sy] = toScreen(robot.shownEstimate[0], robot.shownEstimate[1]);
    drawEllipse(sx, sy, e.covariance, ring);
    ctx.strokeStyle = ring;
    ctx.lineWidth = 2;
    ctx.setLineDash(state === 'converged' ? [] : [4, 3]);
    ctx.beginPath();
    ctx.arc(sx, sy, radius + 3, 0, 2 * Math.PI);
    ctx.moveTo(sx, sy);
    ctx.lineTo(sx + (radius + 8) * Math.cos(robot.shownEstimate[2]), sy - (radius + 8) * Math.sin(robot.shownEstimate[2]));
    ctx.stroke();
    ctx.setLineDash([]);
  }
  const label = robot.shown || robot.shownEstimate;
  if (label) {
    const [sx, sy] = toScreen(label[0], label[1]);
    ctx.fillStyle = '#1d2330';
    ctx.font = '12px system-ui, sans-serif';
    ctx.fillText(robot.name, sx + radius + 6, sy - radius - 4);
  }
}

// The 2σ ellipse of the estimate's (x, y) covariance.
function drawEllipse(sx, sy, c, color) {
  const [xx, xy, yy] = [c[0], c[1], c[4]];
  if (!(xx > 0 && yy > 0)) return;
  const mean = (xx + yy) / 2;
  const spread = Math.sqrt(((xx - yy) / 2) ** 2 + xy * xy);
  const major = 2 * Math.sqrt(mean + spread) * view.scale;
  const minor = 2 * Math.sqrt(Math.max(mean - spread, 0)) * view.scale;
  const angle = 0.5 * Math.atan2(2 * xy, xx - yy);
  if (!(major > 0.5)) return;
  ctx.strokeStyle = color;
  ctx.globalAlpha = 0.8;
  ctx.lineWidth = 1;
  ctx.beginPath();
  ctx.ellipse(sx, sy, major, Math.max(minor, 0.5), -angle, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.globalAlpha = 1;
}

function drawScaleBar() {
  const target = 120;
  const metres = target / view.scale;
  const step = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000].find((s) => s >= metres * 0.5) || 1000;
  const px = step * view.scale;
  const x = 16;
  const y = canvas.height - 18;
  ctx.fillStyle = 'rgba(255,255,255,0.8)';
  ctx.fillRect(x - 6, y - 20, px + 60, 30);
  ctx.strokeStyle = '#1d2330';
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y - 6); ctx.lineTo(x, y); ctx.lineTo(x + px, y); ctx.lineTo(x + px, y - 6);
  ctx.stroke();
  ctx.fillStyle = '#1d2330';
  ctx.font = '12px system-ui, sans-serif';
  ctx.fillText(step >= 1 ? `${step} m` : `${Math.round(step * 100)} cm`, x + px + 6, y);
}

let lastFrame = performance.now();
function frame(now) {
  const dt = Math.min(0.25, (now - lastFrame) / 1000);
  lastFrame = now;
  const started = performance.now();
  resize();
  if (!view.userMoved) fit();
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = '#c9d1dc';
  ctx.fillRect(0, 0, canvas.width, canvas.height);
  drawTiles();
  const robots = [...view.robots.values()];
  for (const robot of robots) drawBeams(robot, colorOf(robot.name));
  for (const robot of robots) drawPaths(robot, colorOf(robot.name));
  for (const robot of robots) drawParticles(robot, colorOf(robot.name));
  for (const robot of robots) drawKidnaps(robot);
  for (const robot of robots) drawGoal(robot, colorOf(robot.name));
  for (const robot of robots) drawRobot(robot, colorOf(robot.name), dt);
  drawScaleBar();
  const ended = performance.now();
  stats.frames.push(now);
  stats.drawMs.push(ended - started);
  if (stats.frames.length > 600) stats.frames.shift();
  if (stats.drawMs.length > 600) stats.drawMs.shift();
  if (stats.frames.length % 30 === 0) {
    const s = window.deogView.stats();
    document.getElementById('stats').textContent =
      `${s.fps.toFixed(0)} fps · draw ${s.drawMsMean.toFixed(1)} ms · ${view.tiles.size} tiles · ${robots.length} robots`;
  }
  requestAnimationFrame(frame);
}

// What tests and curious people can ask the page.
window.deogView = {
  stats() {
    const f = stats.frames;
    const span = f.length > 1 ? (f[f.length - 1] - f[0]) / 1000 : 0;
    const sorted = [...stats.drawMs].sort((a, b) => a - b);
    return {
      fps: span > 0 ? (f.length - 1) / span : 0,
      frames: f.length,
      drawMsMean: sorted.length ? sorted.reduce((a, b) => a + b, 0) / sorted.length : 0,
      drawMsP95: sorted.length ? sorted[Math.floor(sorted.length * 0.95)] : 0,
      tiles: view.tiles.size,
      tileMessages: stats.tileMessages,
      robotMessages: stats.robotMessages,
    };
  },
  resetStats() {
    stats.frames = [];
    stats.drawMs = [];
  },
  tileSeenAt(x, y) {
    const tile = view.tiles.get(x + ',' + y);
    return tile ? tile.seenAt : null;
  },
  mapName() {
    return view.map ? view.map.name : null;
  },
  robots() {
    return [...view.robots.values()].map((r) => ({
      name: r.name,
      marker: r.marker || null,
      truePose: r.data.true_pose,
      estimate: r.data.estimate,
      error: r.data.error,
      kidnaps: r.kidnaps.length,
      particlesShown: r.particles ? r.particles.poses.length : 0,
      truePathPoints: r.truePath.length,
      goal: r.data.goal || null,
      color: colorOf(r.name),
    }));
  },
  toScreen,
};

connect();
requestAnimationFrame(frame);
