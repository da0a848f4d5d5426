// The job report's page logic (docs/DESIGN.md §7 index.html). Reads window.CARVEMAP (report/
// data.js: job.json, each level's plan and top-down map geometry) and draws the summary, the
// time plot, each level's plan over its top-down map (Leaflet, in the job's metres) and the
// 3D model (three.js, mesh/model.glb). #status's attributes say what loaded, for tests.
(function () {
  'use strict';
  const data = window.CARVEMAP || {};
  const job = data.job || {};
  const counts = job.counts || {};
  const status = document.getElementById('status');
  const errors = window.CARVEMAP_ERRORS || [];
  const noteErrors = () => {
    status.dataset.errors = String(errors.length);
    status.dataset.errorList = errors.slice(0, 5).join(' | ');
  };
  const fmt = (v, digits) => {
    if (typeof v !== 'number') return v === undefined ? '—' : String(v);
    const d = digits === undefined ? 2 : digits;
    // No "-0" for a floor a fraction of a millimetre below zero.
    const r = Math.abs(v) < 0.5 * Math.pow(10, -d) ? 0 : v;
    return r.toLocaleString('en', {maximumFractionDigits: d});
  };
  const el = (tag, attrs, text) => {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    return e;
  };

  // ---- summary ----
  document.getElementById('subtitle').textContent =
      (job.job_id ? 'job ' + job.job_id + ' · ' : '') + (job.state || '') +
      (job.command ? ' · ' + [].concat(job.command).join(' ') : '');
  const rooms = job.rooms || [];
  const objects = job.objects || [];
  const carve = job.carve || {};
  const summary = [
    ['rays', carve.rays], ['frames', carve.frames], ['chunks (tiles)', counts.tiles],
    ['levels', (data.levels || []).length], ['rooms', rooms.length], ['objects', objects.length],
    ['dense mesh triangles', counts.dense_triangles], ['building triangles', counts.building_triangles],
    ['object triangles', counts.object_triangles],
    ['observed volume (m³)', counts.observed_volume_m3], ['interior volume (m³)', counts.interior_volume_m3],
  ];
  const table = document.getElementById('summary');
  for (const [name, value] of summary) {
    if (value === undefined) continue;
    const tr = el('tr');
    tr.append(el('td', {}, name), el('td', {class: 'num'}, fmt(value, 1)));
    table.append(tr);
  }
  const warnings = document.getElementById('warnings');
  for (const w of job.warnings || []) warnings.append(el('div', {class: 'warn'}, '⚠ ' + w));

  // ---- where the time went: the job's stages (ingest, carve, merge), then the merge's ----
  const timings = document.getElementById('timings');
  function barChart(title, entries) {
    const bars = entries.filter(([, v]) => typeof v === 'number' && v > 0)
                        .sort((a, b) => b[1] - a[1]).slice(0, 14);
    if (!bars.length) return 0;
    timings.append(el('div', {class: 'note'}, title));
    const max = bars[0][1], rowH = 20, labelW = 190, barW = 260;
    const svg = document.createElementNS('http://www.w3.org/2000/svg', 'svg');
    svg.setAttribute('width', labelW + barW + 70);
    svg.setAttribute('height', bars.length * rowH + 4);
    bars.forEach(([name, secs], i) => {
      const y = i * rowH + 2;
      const label = document.createElementNS(svg.namespaceURI, 'text');
      label.setAttribute('x', labelW - 6); label.setAttribute('y', y + 14);
      label.setAttribute('text-anchor', 'end'); label.textContent = name.replace(/^merge\./, '');
      const bar = document.createElementNS(svg.namespaceURI, 'rect');
      bar.setAttribute('x', labelW); bar.setAttribute('y', y + 3);
      bar.setAttribute('width', Math.max(1, barW * secs / max)); bar.setAttribute('height', rowH - 6);
      bar.setAttribute('fill', '#4a7fb0');
      const value = document.createElementNS(svg.namespaceURI, 'text');
      value.setAttribute('x', labelW + barW * secs / max + 6); value.setAttribute('y', y + 14);
      value.textContent = fmt(secs, 1) + ' s';
      svg.append(label, bar, value);
    });
    timings.append(svg);
    return bars.length;
  }
  const drawn = barChart('the job\'s stages (job.json stage_seconds)', Object.entries(job.stage_seconds || {})) +
      barChart('the merge\'s own stages (job.json timings_s)', Object.entries(job.timings_s || {}).filter(
          ([k]) => k.startsWith('merge.') && k !== 'merge.total' && k !== 'merge.first_outputs'));
  if (!drawn) timings.append(el('div', {class: 'note'}, 'no timings in job.json'));

  // ---- rooms table ----
  const roomTable = document.getElementById('rooms');
  const head = el('tr');
  for (const h of ['level', 'room', 'area (m²)', 'floor (m)', 'ceiling (m)', 'height (m)']) {
    head.append(el('th', {class: h === 'level' || h === 'room' ? '' : 'num'}, h));
  }
  roomTable.append(head);
  for (const r of rooms) {
    const tr = el('tr', {'data-level': r.level, 'data-room': r.room});
    tr.append(el('td', {}, r.level), el('td', {}, r.room), el('td', {class: 'num'}, fmt(r.area_m2, 1)),
              el('td', {class: 'num'}, fmt(r.floor_z)), el('td', {class: 'num'}, fmt(r.ceiling_z)),
              el('td', {class: 'num'}, fmt(r.ceiling_z - r.floor_z)));
    roomTable.append(tr);
  }
  status.dataset.rooms = String(roomTable.querySelectorAll('tr[data-room]').length);
  status.dataset.objects = String(objects.length);

  // ---- floor plans over the top-down maps (Leaflet in the job's metres: lat = y, lng = x) ----
  const levels = data.levels || [];
  let map = null, layers = [];
  function showLevel(k) {
    const level = levels[k];
    for (const b of document.querySelectorAll('#levels button')) b.classList.toggle('on', b.dataset.level == k);
    for (const l of layers) map.removeLayer(l);
    layers = [];
    let bounds = null;
    if (level.topdown) {
      const t = level.topdown;
      const b = L.latLngBounds([t.origin_m[1], t.origin_m[0]],
                               [t.origin_m[1] + t.height * t.resolution_m, t.origin_m[0] + t.width * t.resolution_m]);
      layers.push(L.imageOverlay(t.image, b, {opacity: 0.9}).addTo(map));
      bounds = b;
    }
    if (level.plan) {
      const plan = L.geoJSON(level.plan, {
        style: f => f.properties && f.properties.kind === 'wall'
            ? {color: '#ffcc33', weight: 2}
            : {color: '#5fb3ff', weight: 1, fillOpacity: 0.25},
        onEachFeature: (f, layer) => {
          const p = f.properties || {};
          if (p.kind === 'wall') return;
          layer.bindPopup('room ' + p.room + ' (level ' + p.level + ')<br>' + fmt(p.area_m2, 1) + ' m²<br>floor ' +
                          fmt(p.floor_z) + ' m, ceiling ' + fmt(p.ceiling_z) + ' m');
          layer.bindTooltip(fmt(p.area_m2, 0) + ' m²', {permanent: true, direction: 'center', className: 'room-label'});
        },
      }).addTo(map);
      layers.push(plan);
      if (plan.getLayers().length) bounds = bounds ? bounds.extend(plan.getBounds()) : plan.getBounds();
    }
    if (bounds) map.fitBounds(bounds);
  }
  if (levels.length && window.L) {
    map = L.map('plan', {crs: L.CRS.Simple, minZoom: -4, maxZoom: 6, zoomSnap: 0.25, attributionControl: false});
    const buttons = document.getElementById('levels');
    levels.forEach((level, k) => {
      const b = el('button', {'data-level': k}, 'level ' + level.index);
      b.onclick = () => showLevel(k);
      buttons.append(b);
    });
    showLevel(0);
    status.dataset.plan = 'shown';
  } else {
    document.getElementById('plan').append(el('div', {class: 'note'}, 'no levels'));
    status.dataset.plan = 'none';
  }

  // ---- the 3D model ----
  const canvas = document.getElementById('view');
  const pick = document.getElementById('pick');
  function startViewer() {
    const renderer = new THREE.WebGLRenderer({canvas, antialias: true, preserveDrawingBuffer: true});
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setSize(canvas.clientWidth, canvas.clientHeight, false);
    const scene = new THREE.Scene();
    scene.background = new THREE.Color(0x1d2227);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x445566, 0.65));
    const sun = new THREE.DirectionalLight(0xffffff, 0.45);
    sun.position.set(1, 2, 1.5);
    scene.add(sun);
    const camera = new THREE.PerspectiveCamera(45, canvas.clientWidth / canvas.clientHeight, 0.05, 5000);
    const controls = new THREE.OrbitControls(camera, canvas);
    const groups = {};
    const draw = () => renderer.render(scene, camera);
    controls.addEventListener('change', draw);
    new THREE.GLTFLoader().load(data.model, gltf => {
      const root = gltf.scene;
      root.traverse(o => {
        if (o.name === 'building' || o.name === 'rooms' || o.name === 'objects') groups[o.name] = o;
      });
      // The building's faces face its rooms (docs/DESIGN.md §7), and only front faces are
      // drawn: from outside, the floors and far walls show through the ceilings and near
      // walls, a cut-away view.
      if (groups.rooms) groups.rooms.traverse(o => { if (o.material) o.material.depthWrite = false; });
      scene.add(root);
      const box = new THREE.Box3().setFromObject(root);
      const size = box.getSize(new THREE.Vector3()), centre = box.getCenter(new THREE.Vector3());
      // From above and aside, far enough for the whole box in the 45° view.
      const radius = Math.max(size.length(), 1);
      camera.position.copy(centre).add(new THREE.Vector3(0.6, 0.9, 0.8).normalize().multiplyScalar(1.2 * radius));
      camera.near = radius / 1000; camera.far = radius * 20; camera.updateProjectionMatrix();
      controls.target.copy(centre);
      controls.update();
      for (const name of ['building', 'rooms', 'objects']) {
        const box = document.getElementById('show-' + name);
        box.onchange = () => { if (groups[name]) { groups[name].visible = box.checked; draw(); } };
      }
      draw();
      // The share of the canvas drawn over the background (read back, for the tests).
      const probe = document.createElement('canvas');
      probe.width = 160; probe.height = 120;
      const g = probe.getContext('2d');
      g.drawImage(canvas, 0, 0, probe.width, probe.height);
      const px = g.getImageData(0, 0, probe.width, probe.height).data;
      let lit = 0;
      for (let i = 0; i < px.length; i += 4) {
        if (Math.abs(px[i] - 0x1d) + Math.abs(px[i + 1] - 0x22) + Math.abs(px[i + 2] - 0x27) > 24) ++lit;
      }
      status.dataset.canvasLit = (lit / (px.length / 4)).toFixed(3);
      status.dataset.model = 'loaded';
      noteErrors();
      status.dataset.objectNodes = String(groups.objects ? groups.objects.children.length : 0);
    }, undefined, err => {
      pick.textContent = '3D model not loaded: ' + (err && err.message ? err.message : err) +
          (location.protocol === 'file:' ? ' (browsers do not read files from a page opened as a file: run `carvemap serve OUT`)' : '');
      pick.className = 'warn';
      status.dataset.model = location.protocol === 'file:' ? 'needs-server' : 'error';
      noteErrors();
    });
    // Click: the nearest object under the pointer, else the room.
    const ray = new THREE.Raycaster();
    canvas.addEventListener('click', ev => {
      const r = canvas.getBoundingClientRect();
      ray.setFromCamera(new THREE.Vector2((ev.clientX - r.left) / r.width * 2 - 1,
                                          -(ev.clientY - r.top) / r.height * 2 + 1), camera);
      const hits = ray.intersectObjects(scene.children, true).filter(h => h.object.visible);
      const info = h => { let o = h.object; while (o && !(o.userData && (o.userData.id !== undefined || o.userData.area_m2 !== undefined))) o = o.parent; return o; };
      const objectHit = hits.map(info).find(o => o && o.userData.id !== undefined && o.parent && o.parent.name === 'objects');
      const roomHit = hits.map(info).find(o => o && o.userData.area_m2 !== undefined);
      if (objectHit) {
        const u = objectHit.userData, a = u.aabb || [[0, 0, 0], [0, 0, 0]];
        pick.textContent = 'object ' + u.id + ': ' + [0, 1, 2].map(i => fmt(a[1][i] - a[0][i])).join(' × ') +
            ' m, ' + fmt(u.volume_m3 * 1000, 1) + ' litres, level ' + u.level + ', room ' + u.room;
      } else if (roomHit) {
        const u = roomHit.userData;
        pick.textContent = 'level ' + u.level + ' room ' + u.room + ': ' + fmt(u.area_m2, 1) + ' m², ' +
            fmt(u.ceiling_z - u.floor_z) + ' m high';
      } else {
        pick.textContent = 'nothing there';
      }
      pick.className = '';
    });
  }
  if (!data.model) {
    pick.textContent = 'no 3D model in this job (mesh/model.glb)';
    status.dataset.model = 'none';
  } else if (!window.THREE || !THREE.GLTFLoader) {
    pick.textContent = 'three.js did not load (report/lib/)';
    status.dataset.model = 'error';
  } else {
    try { startViewer(); } catch (e) {
      pick.textContent = '3D view failed: ' + e.message;
      status.dataset.model = 'error';
    }
  }
  noteErrors();
  status.dataset.ready = 'yes';
})();
