// The embodied viewer: draws a ViewScene (computed by `embodied`) with three.js. Nothing here
// computes kinematics: every body's pose at every frame comes with the scene.

// three.js is inline in the page as text; it becomes modules through blob URLs, so the page
// needs no network and no files beside it.
function blobModule(text) {
  return URL.createObjectURL(new Blob([text], { type: 'text/javascript' }));
}
const source = id => document.getElementById(id).textContent;
const coreUrl = blobModule(source('three-core'));
const threeUrl = blobModule(source('three-module').replaceAll('"./three.core.min.js"', JSON.stringify(coreUrl)));
const orbitUrl = blobModule(source('three-orbit').replaceAll("from 'three'", 'from ' + JSON.stringify(threeUrl)));
const THREE = await import(threeUrl);
const { OrbitControls } = await import(orbitUrl);

const scene = JSON.parse(source('scene-data'));
const frames = scene.times.length;
const $ = id => document.getElementById(id);
$('title').textContent = scene.title;
$('source').textContent = scene.source + ' · ' + scene.generator;

// Renderer, camera (z up, as the robots' world), lights, floor.
const container = $('view');
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio || 1);
container.appendChild(renderer.domElement);
const world = new THREE.Scene();
world.background = new THREE.Color(0xf4f5f7);
const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 200);
camera.up.set(0, 0, 1);
world.add(new THREE.HemisphereLight(0xffffff, 0x808080, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(3, -2, 5);
world.add(sun);

function geometryOf(shape) {
  let g;
  switch (shape.kind) {
    case 'box': g = new THREE.BoxGeometry(shape.size[0], shape.size[1], shape.size[2]); break;
    case 'sphere': g = new THREE.SphereGeometry(shape.radius, 24, 16); break;
    case 'cylinder': g = new THREE.CylinderGeometry(shape.radius, shape.radius, shape.length, 24); g.rotateX(Math.PI / 2); break;
    case 'capsule': g = new THREE.CapsuleGeometry(shape.radius, shape.length, 6, 16); g.rotateX(Math.PI / 2); break;
    case 'mesh': {
      g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.Float32BufferAttribute(shape.vertices, 3));
      g.setIndex(shape.triangles);
      g = g.toNonIndexed();
      g.computeVertexNormals();
      break;
    }
    default: throw new Error('unknown shape kind ' + shape.kind);
  }
  return g;
}

function setPose(object, p) {
  object.position.set(p[0], p[1], p[2]);
  object.quaternion.set(p[3], p[4], p[5], p[6]);
}

const bodies = scene.bodies.map(body => {
  const group = new THREE.Group();
  const material = new THREE.MeshStandardMaterial({
    color: new THREE.Color(body.color),
    roughness: 0.6,
    metalness: body.kind === 'link' ? 0.2 : 0.0,
    transparent: body.kind === 'obstacle',
    opacity: body.kind === 'obstacle' ? 0.75 : 1.0,
  });
  for (const shape of body.shapes) {
    const mesh = new THREE.Mesh(geometryOf(shape), material);
    setPose(mesh, shape.pose);
    group.add(mesh);
    const edges = new THREE.LineSegments(new THREE.EdgesGeometry(mesh.geometry, 30), new THREE.LineBasicMaterial({ color: 0x333333, transparent: true, opacity: 0.25 }));
    setPose(edges, shape.pose);
    group.add(edges);
  }
  world.add(group);
  return { body, group };
});

// Frame the scene: every body at the first frame, plus a floor under it.
function showFrame(i) {
  for (const { body, group } of bodies) {
    const p = body.poses.length === 1 ? body.poses[0] : body.poses[i];
    group.visible = p !== null && p !== undefined;
    if (group.visible) setPose(group, p);
  }
}
showFrame(0);
const box = new THREE.Box3();
for (const { group } of bodies) if (group.visible) box.expandByObject(group);
if (box.isEmpty()) box.set(new THREE.Vector3(-1, -1, 0), new THREE.Vector3(1, 1, 1));
const centre = box.getCenter(new THREE.Vector3());
const size = box.getSize(new THREE.Vector3());
const span = Math.max(size.x, size.y, size.z, 0.5);
const gridSize = Math.ceil(span * 1.6);
const grid = new THREE.GridHelper(gridSize, gridSize * 10, 0xb0b0b0, 0xdedede);
grid.rotateX(Math.PI / 2);
grid.position.set(centre.x, centre.y, Math.min(box.min.z, 0));
world.add(grid);
world.add(new THREE.AxesHelper(0.3));
camera.position.set(centre.x + span * 1.05, centre.y - span * 0.85, centre.z + span * 0.8);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.copy(centre);
controls.update();

// Timeline: slider, event marks, event list.
const slider = $('slider');
slider.max = String(Math.max(frames - 1, 0));
const duration = frames > 0 ? scene.times[frames - 1] : 0;
const frameOf = t => Math.max(0, Math.min(frames - 1, Math.round(t / scene.frame_s)));
const eventRows = [];
scene.events.forEach(e => {
  const jump = () => { setTime(e.t); playing = false; updatePlay(); };
  if (e.kind !== 'other') {
    const mark = document.createElement('div');
    mark.className = 'mark kind-' + e.kind;
    mark.style.left = (duration > 0 ? (100 * e.t / duration) : 0) + '%';
    mark.title = `t=${e.t.toFixed(3)} s  ${e.agent}: ${e.label}`;
    mark.addEventListener('click', jump);
    $('marks').appendChild(mark);
  }
  const row = document.createElement('div');
  row.className = 'kind-row-' + e.kind;
  row.textContent = `${e.t.toFixed(3)} s  ${e.agent}: ${e.label}`;
  row.title = row.textContent;
  row.addEventListener('click', jump);
  $('events').appendChild(row);
  eventRows.push([e, row]);
});

let time = 0;
let frame = 0;
let playing = true;
let speed = 1;
function setTime(t) {
  time = Math.max(0, Math.min(duration, t));
  frame = frameOf(time);
  slider.value = String(frame);
  showFrame(frame);
  const c = scene.clearance[frame];
  $('clearance').textContent = c ? `clearance ${(c.m * 1000).toFixed(1)} mm: ${c.a} to ${c.b}` : 'clearance: nothing near';
  $('time').textContent = `t = ${scene.times[frame]?.toFixed(3) ?? '0.000'} s of ${duration.toFixed(3)} s`;
  for (const [e, row] of eventRows) row.classList.toggle('now', Math.abs(e.t - time) < scene.frame_s);
  document.body.dataset.frame = String(frame);
}
function updatePlay() { $('play').textContent = playing ? 'Pause' : 'Play'; }
$('play').addEventListener('click', () => {
  if (!playing && time >= duration) setTime(0);
  playing = !playing;
  updatePlay();
});
$('speed').addEventListener('change', e => { speed = Number(e.target.value); });
slider.addEventListener('input', () => { setTime(Number(slider.value) * scene.frame_s); playing = false; updatePlay(); });

// A URL hash `#t=SECONDS` opens the page paused at that time.
const hashTime = /(?:^#|&)t=([0-9.]+)/.exec(location.hash);
if (hashTime) { playing = false; setTime(Number(hashTime[1])); } else { setTime(0); }
updatePlay();

function resize() {
  const w = container.clientWidth || 800, h = container.clientHeight || 600;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();

let last = performance.now();
function tick(now) {
  const dt = Math.min(0.1, (now - last) / 1000);
  last = now;
  if (playing) {
    setTime(time + dt * speed);
    if (time >= duration) { playing = false; updatePlay(); }
  }
  controls.update();
  renderer.render(world, camera);
  requestAnimationFrame(tick);
}
renderer.render(world, camera);
const meshes = bodies.reduce((n, b) => n + b.group.children.length / 2, 0);
document.body.dataset.meshes = String(meshes);
if (window.__viewerErrors.length === 0) {
  document.body.dataset.status = 'ok';
}
requestAnimationFrame(tick);
