// laserline-view's page: server-sent events from /events, frames from /frame.jpg, drawn on
// canvases. Nothing else is loaded.
'use strict';

// Errors are shown on the page and counted in body[data-errors] (the browser test reads it).
const errorList = document.getElementById('errors');
function noteError(text) {
  document.body.dataset.errors = String(Number(document.body.dataset.errors) + 1);
  if (errorList.children.length < 5) {
    const item = document.createElement('li');
    item.textContent = text;
    errorList.appendChild(item);
  }
}
window.addEventListener('error', (e) => {
  noteError(e.message || ('could not load ' + ((e.target && (e.target.src || e.target.href)) || 'a resource')));
}, true);
window.addEventListener('unhandledrejection', (e) => noteError(String(e.reason)));

const $ = (id) => document.getElementById(id);

function fixed(value, decimals) {
  return value === null || value === undefined ? '–' : Number(value).toFixed(decimals);
}

function setRows(table, rows) {
  const body = table.tBodies[0];
  while (body.rows.length < rows.length) {
    const row = body.insertRow();
    row.insertCell();
    row.insertCell().className = 'num';
  }
  while (body.rows.length > rows.length) body.deleteRow(-1);
  rows.forEach(([label, value, cls], i) => {
    const cells = body.rows[i].cells;
    cells[0].textContent = label;
    cells[1].textContent = value;
    cells[1].className = 'num ' + (cls || '');
  });
}

// --- status ---------------------------------------------------------------------------------
let lastStatusAt = 0;
function showStatus(s) {
  lastStatusAt = performance.now();
  document.body.dataset.statuses = String(Number(document.body.dataset.statuses) + 1);
  controlsKnowStatus(s);
  const cameraClass = s.camera_state === 'streaming' ? 'ok' : 'bad';
  const dropped = s.frames_dropped + s.profiles_dropped + s.images_dropped;
  setRows($('status'), [
    ['frames/s', fixed(s.frame_rate_hz, 1)],
    ['camera', s.camera_backend + ', ' + s.camera_state, cameraClass],
    ['laser', (s.laser_on ? 'on' : 'off') + ', ' + s.laser_switches + ' switches',
      s.laser_on ? 'warn' : ''],
    ['detector', s.detector + ', ' + fixed(s.points_per_profile, 1) + ' points/profile'],
    ['latency p50 / p99 / max', fixed(s.latency_p50_ms, 2) + ' / ' + fixed(s.latency_p99_ms, 2) +
      ' / ' + fixed(s.latency_max_ms, 2) + ' ms'],
    ['pipeline p50 / p99', fixed(s.pipeline_p50_ms, 2) + ' / ' + fixed(s.pipeline_p99_ms, 2) + ' ms'],
    ['frames captured / processed', s.frames_captured + ' / ' + s.frames_processed],
    ['dropped frames / profiles / images', s.frames_dropped + ' / ' + s.profiles_dropped + ' / ' +
      s.images_dropped, dropped > 0 ? 'warn' : ''],
    ['over budget, processing max', s.frames_over_budget + ', ' + fixed(s.processing_max_ms, 2) + ' ms'],
    ['CPU', fixed(s.cpu_percent, 1) + ' % of a core'],
    ['grab timeouts / errors', s.grab_timeouts + ' / ' + s.grab_errors,
      s.grab_timeouts + s.grab_errors > 0 ? 'warn' : ''],
    ['laser safety offs / errors / late', s.laser_safety_offs + ' / ' + s.laser_errors + ' / ' +
      s.laser_late_switches, s.laser_safety_offs + s.laser_errors > 0 ? 'bad' : ''],
    ['camera reconnects / skipped', s.camera_reconnects + ' / ' + s.camera_skipped_frames],
    ['bad input messages / frames', s.bad_messages + ' / ' + s.bad_frames,
      s.bad_messages + s.bad_frames > 0 ? 'warn' : ''],
    ['publish errors', String(s.publish_errors), s.publish_errors > 0 ? 'warn' : ''],
    ['uptime', fixed(s.uptime_us / 1e6, 0) + ' s'],
    ['instance', s.instance_id],
  ]);
}

function showViewer(v) {
  const rows = v.channels.map((c) => [c.name,
    c.received + ' received, ' + c.malformed + ' malformed' +
      (c.age_s === null ? '' : ', last ' + fixed(c.age_s, 1) + ' s ago'),
    c.malformed > 0 ? 'warn' : (c.age_s === null || c.age_s > 3 ? 'bad' : '')]);
  rows.push(['live views open', String(v.streams)]);
  setRows($('viewer'), rows);
  $('problem').textContent = v.last_problem ? 'last malformed message: ' + v.last_problem : '';
  $('history').textContent = String(v.history_s);
  historyMs = v.history_s * 1000;
  const status = v.channels[2];
  $('status-info').textContent = status.age_s === null ? '(none received)' :
    (status.age_s > 3 ? '(stale: ' + fixed(status.age_s, 0) + ' s old)' : '');
}

// --- raw frame with its points ---------------------------------------------------------------
const frameCanvas = $('frame');
const frameContext = frameCanvas.getContext('2d');
let frameLoading = false;
let pendingFrame = null;

function frameArrived(f) {
  pendingFrame = f;
  if (!frameLoading) loadFrame();
}

function loadFrame() {
  const f = pendingFrame;
  pendingFrame = null;
  if (!f) return;
  frameLoading = true;
  const image = new Image();
  image.onload = () => {
    drawFrame(image, f);
    frameLoading = false;
    loadFrame();
  };
  image.onerror = () => {
    frameLoading = false;
    $('frame-info').textContent = 'frame ' + f.sequence + ' did not load';
    loadFrame();
  };
  image.src = 'frame.jpg?sequence=' + f.sequence;
}

// The region in force and one being dragged (frame pixels x, y, width, height), outlined on
// the frame; where the frame lies on the canvas.
let regionInForce = null;
let dragged = null;
let frameGeometry = null;
let lastFrame = null;

function drawFrame(image, f) {
  lastFrame = {image: image, f: f};
  redrawFrame();
  document.body.dataset.frames = String(Number(document.body.dataset.frames) + 1);
  $('frame-info').textContent = 'frame ' + f.sequence + ', ' + f.width + '×' + f.height +
    ', laser ' + (f.laser_on ? 'on' : 'off') + ', ' +
    (f.profile ? (f.points.length / 2) + ' points' : 'its profile not received');
}

function redrawFrame() {
  if (!lastFrame) return;
  const {image, f} = lastFrame;
  const cw = frameCanvas.width, ch = frameCanvas.height;
  const scale = Math.min(cw / image.naturalWidth, ch / image.naturalHeight);
  const w = image.naturalWidth * scale, h = image.naturalHeight * scale;
  const x0 = (cw - w) / 2, y0 = (ch - h) / 2;
  // The image may be a part of the camera's frame, downscaled: a camera pixel's edge X lies at
  // (X - roi_x) / downscale in the image.
  frameGeometry = {x0: x0, y0: y0, scale: scale, roiX: f.roi_x, roiY: f.roi_y, k: f.downscale,
    width: f.roi_x + f.downscale * image.naturalWidth,
    height: f.roi_y + f.downscale * image.naturalHeight};
  frameCanvas.dataset.geometry = [x0, y0, scale, f.roi_x, f.roi_y, f.downscale].join(',');
  frameContext.fillStyle = '#000';
  frameContext.fillRect(0, 0, cw, ch);
  frameContext.imageSmoothingEnabled = scale < 1;
  frameContext.drawImage(image, x0, y0, w, h);
  // The points were given in the frame's pixels (centres at integers).
  const dots = (points, colour) => {
    frameContext.fillStyle = colour;
    for (let i = 0; i + 1 < points.length; i += 2) {
      const x = x0 + (points[i] + 0.5) * scale, y = y0 + (points[i + 1] + 0.5) * scale;
      frameContext.fillRect(x - 1, y - 1, 2, 2);
    }
  };
  dots(f.candidates, '#35a7ff');
  dots(f.points, '#ff3b30');
  const outline = (r, colour, dash) => {
    const s = scale / f.downscale;
    frameContext.strokeStyle = colour;
    frameContext.lineWidth = 1;
    frameContext.setLineDash(dash);
    frameContext.strokeRect(x0 + (r[0] - f.roi_x) * s + 0.5, y0 + (r[1] - f.roi_y) * s + 0.5,
      r[2] * s - 1, r[3] * s - 1);
    frameContext.setLineDash([]);
  };
  if (regionInForce) outline(regionInForce, '#ffcc00', []);
  if (dragged) outline(dragged, '#ffffff', [4, 3]);
}

// --- profile plot ---------------------------------------------------------------------------
const profileCanvas = $('profile');
const profileContext = profileCanvas.getContext('2d');

function niceStep(span) {
  const raw = span / 6;
  const magnitude = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 5, 10]) {
    if (m * magnitude >= raw) return m * magnitude;
  }
  return 10 * magnitude;
}

// Plots pairs (a, b) of `series` (each {pairs, colour}) with a horizontally, b vertically
// (increasing downwards when `down`).
function plot(context, series, labelA, labelB, down) {
  const cw = context.canvas.width, ch = context.canvas.height;
  const left = 52, right = 10, top = 10, bottom = 30;
  context.fillStyle = '#000';
  context.fillRect(0, 0, cw, ch);
  let minA = Infinity, maxA = -Infinity, minB = Infinity, maxB = -Infinity;
  for (const s of series) {
    for (let i = 0; i + 1 < s.pairs.length; i += 2) {
      minA = Math.min(minA, s.pairs[i]); maxA = Math.max(maxA, s.pairs[i]);
      minB = Math.min(minB, s.pairs[i + 1]); maxB = Math.max(maxB, s.pairs[i + 1]);
    }
  }
  context.font = '11px system-ui, sans-serif';
  context.fillStyle = '#8d98a5';
  if (minA > maxA) {
    context.fillText('no points in this profile', left, top + 20);
    return;
  }
  const padA = Math.max((maxA - minA) * 0.05, 1), padB = Math.max((maxB - minB) * 0.1, 1);
  minA -= padA; maxA += padA; minB -= padB; maxB += padB;
  const sx = (cw - left - right) / (maxA - minA), sy = (ch - top - bottom) / (maxB - minB);
  const px = (a) => left + (a - minA) * sx;
  const py = (b) => down ? top + (b - minB) * sy : ch - bottom - (b - minB) * sy;
  context.strokeStyle = '#2c333b';
  context.lineWidth = 1;
  const stepA = niceStep(maxA - minA), stepB = niceStep(maxB - minB);
  context.textAlign = 'center';
  for (let a = Math.ceil(minA / stepA) * stepA; a <= maxA; a += stepA) {
    context.beginPath(); context.moveTo(px(a), top); context.lineTo(px(a), ch - bottom); context.stroke();
    context.fillText(String(Math.round(a * 100) / 100), px(a), ch - bottom + 13);
  }
  context.textAlign = 'right';
  for (let b = Math.ceil(minB / stepB) * stepB; b <= maxB; b += stepB) {
    context.beginPath(); context.moveTo(left, py(b)); context.lineTo(cw - right, py(b)); context.stroke();
    context.fillText(String(Math.round(b * 100) / 100), left - 4, py(b) + 4);
  }
  context.textAlign = 'center';
  context.fillText(labelA, left + (cw - left - right) / 2, ch - 4);
  context.save();
  context.translate(12, top + (ch - top - bottom) / 2);
  context.rotate(-Math.PI / 2);
  context.fillText(labelB, 0, 0);
  context.restore();
  context.textAlign = 'left';
  for (const s of series) {
    context.fillStyle = s.colour;
    for (let i = 0; i + 1 < s.pairs.length; i += 2) {
      context.fillRect(px(s.pairs[i]) - 1, py(s.pairs[i + 1]) - 1, 2, 2);
    }
  }
}

function showProfile(p) {
  document.body.dataset.profiles = String(Number(document.body.dataset.profiles) + 1);
  $('profile-info').textContent = 'frame ' + p.sequence + ', ' + p.detector + ', ' + p.valid +
    ' points' + (p.points > p.valid ? ', ' + (p.points - p.valid) + ' rejected' : '');
  if (p.uv) {
    // Not triangulated: the line in the image, position along each searched line.
    plot(profileContext, [{pairs: p.uv, colour: '#ff3b30'}], 'searched line u (px)',
      'position along it v (px)', true);
  } else {
    plot(profileContext, [{pairs: p.candidates_xz, colour: '#35a7ff'}, {pairs: p.xz, colour: '#ff3b30'}],
      'X across (mm)', 'Z range (mm)', false);
  }
  const now = performance.now();
  for (const chunk of p.cloud) cloud.push({at: now - chunk.age_ms, xyz: chunk.xyz});
}

// --- 3-D points of the last seconds --------------------------------------------------------
// Each profile's points lie in the laser sheet; laid out along time (the vehicle's motion is not
// known here) the last seconds form a surface: across (X) by time, range (Z) as height and
// colour, seen from above at a slowly turning angle.
const cloudCanvas = $('cloud');
const cloudContext = cloudCanvas.getContext('2d');
const cloud = [];
let historyMs = 5000;
let lastCloudDraw = 0;

function drawCloud(now) {
  requestAnimationFrame(drawCloud);
  if (now - lastCloudDraw < 50) return;
  lastCloudDraw = now;
  while (cloud.length > 0 && cloud[0].at < now - historyMs) cloud.shift();
  const cw = cloudCanvas.width, ch = cloudCanvas.height;
  cloudContext.fillStyle = '#000';
  cloudContext.fillRect(0, 0, cw, ch);
  let n = 0, minX = Infinity, maxX = -Infinity, minZ = Infinity, maxZ = -Infinity;
  for (const c of cloud) {
    for (let i = 0; i + 2 < c.xyz.length; i += 3) {
      minX = Math.min(minX, c.xyz[i]); maxX = Math.max(maxX, c.xyz[i]);
      minZ = Math.min(minZ, c.xyz[i + 2]); maxZ = Math.max(maxZ, c.xyz[i + 2]);
      ++n;
    }
  }
  cloudContext.fillStyle = '#8d98a5';
  cloudContext.font = '11px system-ui, sans-serif';
  if (n === 0) {
    cloudContext.fillText('no triangulated points yet', 10, 20);
    return;
  }
  // Time spans as much as the points do across; range (height) keeps its true scale to X.
  const spanX = Math.max(maxX - minX, 1), spanZ = Math.max(maxZ - minZ, 1);
  const alongPerMs = spanX / historyMs;
  const cx = (minX + maxX) / 2, cz = (minZ + maxZ) / 2;
  const yaw = 0.5 * Math.sin(now / 5000), pitch = 0.75;
  const cosY = Math.cos(yaw), sinY = Math.sin(yaw), cosP = Math.cos(pitch), sinP = Math.sin(pitch);
  // Projected first, then fitted to the canvas.
  const projected = new Float32Array(3 * n);
  let k = 0, minU = Infinity, maxU = -Infinity, minV = Infinity, maxV = -Infinity;
  for (const c of cloud) {
    const along = (now - c.at - historyMs / 2) * alongPerMs;  // newest at the front (bottom)
    for (let i = 0; i + 2 < c.xyz.length; i += 3) {
      const a = c.xyz[i] - cx, h = cz - c.xyz[i + 2];
      const u = cosY * a + sinY * along, depth = -sinY * a + cosY * along;
      const v = -depth * cosP - h * sinP;
      projected[k++] = u;
      projected[k++] = v;
      projected[k++] = c.xyz[i + 2];
      minU = Math.min(minU, u); maxU = Math.max(maxU, u);
      minV = Math.min(minV, v); maxV = Math.max(maxV, v);
    }
  }
  const scale = 0.9 * Math.min(cw / Math.max(maxU - minU, 1), (ch - 24) / Math.max(maxV - minV, 1));
  const u0 = cw / 2 - scale * (minU + maxU) / 2, v0 = (ch - 24) / 2 - scale * (minV + maxV) / 2;
  for (let i = 0; i < k; i += 3) {
    const hue = 240 * (projected[i + 2] - minZ) / spanZ;
    cloudContext.fillStyle = 'hsl(' + hue.toFixed(0) + ',90%,55%)';
    cloudContext.fillRect(u0 + projected[i] * scale, v0 + projected[i + 1] * scale, 1.5, 1.5);
  }
  cloudContext.fillStyle = '#8d98a5';
  cloudContext.fillText(n + ' points; range ' + fixed(minZ, 0) + '–' + fixed(maxZ, 0) +
    ' mm (red near, blue far); across × time, newest in front', 10, ch - 8);
}
requestAnimationFrame(drawCloud);

// --- the event stream -------------------------------------------------------------------------
function listen() {
  const events = new EventSource('events');
  const connection = $('connection');
  events.onopen = () => {
    connection.textContent = 'live';
    connection.className = 'ok';
  };
  events.onerror = () => {
    connection.textContent = 'disconnected, retrying';
    connection.className = 'bad';
  };
  const handle = (name, show) => events.addEventListener(name, (e) => {
    try {
      show(JSON.parse(e.data));
    } catch (error) {
      noteError(name + ' event: ' + error);
    }
  });
  handle('status', showStatus);
  handle('viewer', showViewer);
  handle('profile', showProfile);
  handle('frame', frameArrived);
}
listen();
$('source').textContent = location.host;

// --- controls: shown when laserline-view runs with --allow-control ---------------------------
// The detector's threshold is named by the detector (status.detector).
let detectorName = null;
let prefixChosen = false;
function controlsKnowStatus(s) {
  detectorName = s.detector;
  $('threshold-label').textContent = s.detector === 'maxvalue' ? 'threshold (grey level)'
                                                               : 'threshold (SNR dB)';
  if (!prefixChosen) {
    prefixChosen = true;
    $('feature-prefix').value = s.camera_backend === 'v4l2' ? 'v4l2:' : 'genicam:';
  }
}
function thresholdName() {
  return detectorName === 'maxvalue' ? 'detector.maxvalue.threshold'
                                     : 'detector.frontend.snr_threshold_db';
}

// "x,y,width,height" into the region's fields and the outline on the frame.
function showRegion(text) {
  const parts = text.split(',').map(Number);
  if (parts.length !== 4 || parts.some((n) => !Number.isInteger(n))) return;
  ['roi-x', 'roi-y', 'roi-w', 'roi-h'].forEach((id, i) => { $(id).value = String(parts[i]); });
  regionInForce = parts;
  redrawFrame();
}

// The answer of "get": "name=value" for each setting in force, into the fields.
function showValuesInForce(text) {
  const fields = {exposure_us: 'exposure', gain_db: 'gain', frame_rate_hz: 'frame-rate',
    'laser.mode': 'laser-mode'};
  fields[thresholdName()] = 'threshold';
  for (const pair of text.split(' ')) {
    const at = pair.indexOf('=');
    if (at < 0) continue;
    const name = pair.slice(0, at), value = pair.slice(at + 1);
    if (name === 'detector.roi') showRegion(value);
    else if (fields[name]) $(fields[name]).value = value;
  }
}

function sendCommand(name, value) {
  const ack = $('ack');
  ack.textContent = name + ' ' + value + ' …';
  ack.className = 'info';
  const body = new URLSearchParams({name: name, value: value, token: $('token').value});
  fetch('command', {method: 'POST', body: body})
    .then((response) => response.json())
    .then((a) => {
      if (!a.accepted) {
        ack.textContent = 'refused: ' + a.reason + (a.value ? ' (in force: ' + a.value + ')' : '');
      } else if (a.name === 'get') {
        ack.textContent = 'in force: ' + a.value;
        showValuesInForce(a.value);
      } else {
        ack.textContent = a.name + ' = ' + a.value + ' (was ' + a.old_value + ')';
        if (a.name === 'detector.roi') showRegion(a.value);
      }
      ack.className = a.accepted ? 'ok' : 'bad';
      document.body.dataset.acks = String(Number(document.body.dataset.acks) + 1);
    })
    .catch((error) => noteError('command: ' + error));
}

// A rectangle dragged on the frame fills in the region's fields (sent with "set"): from the
// camera pixel under the pointer where it was pressed to the one where it was released.
function framePixel(e) {
  const box = frameCanvas.getBoundingClientRect();
  const g = frameGeometry;
  const pixel = (canvas, origin, roi, limit) =>
    Math.min(Math.max(Math.floor(roi + g.k * (canvas - origin) / g.scale), roi), limit);
  return [pixel((e.clientX - box.left) * frameCanvas.width / box.width, g.x0, g.roiX, g.width),
    pixel((e.clientY - box.top) * frameCanvas.height / box.height, g.y0, g.roiY, g.height)];
}
function enableRegionDragging() {
  frameCanvas.classList.add('controlled');
  let from = null;
  frameCanvas.addEventListener('mousedown', (e) => {
    if (!frameGeometry) return;
    from = framePixel(e);
    e.preventDefault();
  });
  frameCanvas.addEventListener('mousemove', (e) => {
    if (!from) return;
    const to = framePixel(e);
    dragged = [Math.min(from[0], to[0]), Math.min(from[1], to[1]), Math.abs(to[0] - from[0]),
      Math.abs(to[1] - from[1])];
    redrawFrame();
  });
  window.addEventListener('mouseup', () => {
    if (!from) return;
    from = null;
    if (dragged && dragged[2] >= 1 && dragged[3] >= 1) {
      ['roi-x', 'roi-y', 'roi-w', 'roi-h'].forEach((id, i) => { $(id).value = String(dragged[i]); });
    }
    dragged = null;
    redrawFrame();
  });
}

fetch('control')
  .then((response) => response.json())
  .then((control) => {
    if (!control.allowed) return;
    $('controls').hidden = false;
    const on = (id, send) => $(id).addEventListener('click', send);
    on('set-exposure', () => sendCommand('exposure_us', $('exposure').value));
    on('set-gain', () => sendCommand('gain_db', $('gain').value));
    on('set-frame-rate', () => sendCommand('frame_rate_hz', $('frame-rate').value));
    on('set-laser', () => sendCommand('laser.mode', $('laser-mode').value));
    on('set-threshold', () => sendCommand(thresholdName(), $('threshold').value));
    on('set-roi', () => sendCommand('detector.roi',
      ['roi-x', 'roi-y', 'roi-w', 'roi-h'].map((id) => $(id).value.trim()).join(',')));
    on('full-roi', () => sendCommand('detector.roi', 'full'));
    on('set-feature', () => sendCommand($('feature-prefix').value + $('feature-name').value.trim(),
      $('feature-value').value));
    on('get-all', () => sendCommand('get', ''));
    enableRegionDragging();
  })
  .catch((error) => noteError('control: ' + error));

// Where the frame is, for the browser test's screenshots.
const rect = frameCanvas.getBoundingClientRect();
frameCanvas.dataset.rect = [rect.left, rect.top, rect.width, rect.height].map(Math.round).join(',');
document.body.dataset.ready = '1';
