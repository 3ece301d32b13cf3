// The viewer of viewer.html: one 3D Tiles tileset from `dbms export mesh`, drawn by three.js
// through 3d-tiles-renderer, in the tileset's local frame rather than on the globe.
//
// Query parameters:
//   tileset=URL     the tileset.json (required)
//   camera=E,N,U    camera position, metres in the tileset's local frame (x east, y north,
//                   z up, from the export's origin); default: from the south-west, 45° down
//                   onto the target, as close as the root tile's box allows while all of it
//                   stays in view
//   target=E,N,U    the point looked at (default: the root box's centre, or without a camera
//                   given, slid along the ground until the box is centred in the view)
//   fov=DEG         vertical field of view (default 40)
//   sun=AZ,EL       the directional light's azimuth (clockwise from grid north) and elevation,
//                   degrees (default 127.3,32.3: the sample orthophoto's sun, so lit walls are
//                   shaded as the photo's shadows fall)
//   error=PX        3d-tiles-renderer's errorTarget: a tile is replaced by its children while
//                   its geometric error would show as more than PX pixels (default 8; 0: the
//                   finest level everywhere in view)
//
// The tileset's root `transform` (local frame -> ECEF) is inverted, so the tiles come back to
// the local frame, which is then turned z-up -> y-up for three.js: (E, N, U) -> (E, U, -N).
//
// For a screenshot script: once the root tileset is in, every tile the view wants has loaded
// and nothing has changed for SETTLE_FRAMES frames, `window.__dbmsReady` is set to
// {tiles, triangles} (drawn); any failure sets
// `window.__dbmsError` to its message instead.

import * as THREE from "three";
import { TilesRenderer } from "3d-tiles-renderer";

/** Frames in a row with nothing loading before the view counts as complete. */
const SETTLE_FRAMES = 10;
const SKY = 0xb9cfe4;

function fail(message) {
  if (window.__dbmsError === undefined) {
    window.__dbmsError = String(message);
    console.error(`viewer: ${message}`);
  }
}
window.addEventListener("error", (e) => fail(e.message));
window.addEventListener("unhandledrejection", (e) => fail(e.reason?.message ?? e.reason));

const params = new URLSearchParams(location.search);

/** A query parameter as `n` comma-separated numbers, or `fallback` when absent. */
function numbers(name, n, fallback) {
  const text = params.get(name);
  if (text === null) return fallback;
  const v = text.split(",").map(Number);
  if (v.length !== n || !v.every(Number.isFinite)) {
    throw new Error(`query parameter ${name}=${text}: expected ${n} comma-separated numbers`);
  }
  return v;
}

/** Local frame (east, north, up) -> three.js (x, y up, z towards the viewer = south). */
function toThree([e, n, u]) {
  return new THREE.Vector3(e, u, -n);
}

/** The 8 corners and the centre of a 3D Tiles `box` (centre, then three half-axis vectors). */
function boxCorners(box) {
  const [cx, cy, cz, ...axes] = box;
  const corners = [];
  for (const sx of [-1, 1]) {
    for (const sy of [-1, 1]) {
      for (const sz of [-1, 1]) {
        corners.push([0, 1, 2].map((k) => [cx, cy, cz][k] + sx * axes[k] + sy * axes[3 + k] + sz * axes[6 + k]));
      }
    }
  }
  return { centre: [cx, cy, cz], corners };
}

/** Look from the south-west, 45° down. */
const VIEW_DIR = [-0.5, -0.5, Math.SQRT1_2];

/** Put `camera` at `d` metres along VIEW_DIR from `target`, looking at it. */
function lookFrom(camera, target, d) {
  camera.position.copy(toThree(target.map((t, k) => t + d * VIEW_DIR[k])));
  camera.lookAt(toThree(target));
  camera.updateMatrixWorld();
}

/**
 * The smallest distance (to 1 %) from `target` along VIEW_DIR at which every corner is in
 * front of the camera and inside 95 % of the view; leaves the camera there.
 */
function fitDistance(camera, target, corners) {
  const fits = (d) => {
    lookFrom(camera, target, d);
    return corners.every((c) => {
      const p = toThree(c).project(camera);
      return p.z < 1 && Math.abs(p.x) <= 0.95 && Math.abs(p.y) <= 0.95;
    });
  };
  let lo = 0;
  let hi = Math.max(...corners.map((c) => Math.hypot(c[0] - target[0], c[1] - target[1], c[2] - target[2])));
  while (!fits(hi)) hi *= 2;
  while (hi - lo > 0.01 * hi) {
    const mid = (lo + hi) / 2;
    if (fits(mid)) hi = mid;
    else lo = mid;
  }
  lookFrom(camera, target, hi);
  return hi;
}

/**
 * The default view of a box: from the south-west, 45° down, its corners filling the view. A
 * box seen obliquely projects larger at its near side, so the target is slid along the ground
 * (towards the north-east or back) until the projected corners sit centred top to bottom.
 * Returns [eye, target].
 */
function frameBox(camera, centre, corners) {
  const target = [...centre];
  let d = 0;
  for (let i = 0; i < 8; i++) {
    d = fitDistance(camera, target, corners);
    const ys = corners.map((c) => toThree(c).project(camera).y);
    const mid = (Math.min(...ys) + Math.max(...ys)) / 2;
    // NDC y of 1 is tan(fov/2)·d metres at the target, d·tan(fov/2)·√2 along the 45° ground.
    const slide = mid * d * Math.tan(THREE.MathUtils.degToRad(camera.fov / 2)) * Math.SQRT2;
    target[0] += slide * Math.SQRT1_2;
    target[1] += slide * Math.SQRT1_2;
  }
  return [target.map((t, k) => t + d * VIEW_DIR[k]), target];
}

function main() {
  const url = params.get("tileset");
  if (!url) throw new Error("no tileset: give ?tileset=URL of a tileset.json");
  const fov = numbers("fov", 1, [40])[0];
  const [sunAz, sunEl] = numbers("sun", 2, [127.3, 32.3]).map(THREE.MathUtils.degToRad);

  const renderer = new THREE.WebGLRenderer({ antialias: true });
  renderer.setPixelRatio(1);
  renderer.setSize(innerWidth, innerHeight);
  renderer.setClearColor(SKY);
  document.body.appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(fov, innerWidth / innerHeight, 1, 10000);
  scene.add(new THREE.HemisphereLight(0xdde8ff, 0x6b5f4a, 1.2));
  const sun = new THREE.DirectionalLight(0xfff6e8, 2.2);
  sun.position.copy(toThree([Math.sin(sunAz) * Math.cos(sunEl), Math.cos(sunAz) * Math.cos(sunEl), Math.sin(sunEl)]));
  scene.add(sun);

  const tiles = new TilesRenderer(url);
  tiles.errorTarget = numbers("error", 1, [8])[0];
  tiles.setCamera(camera);
  tiles.setResolutionFromRenderer(camera, renderer);
  scene.add(tiles.group);

  let placed = false;
  let settled = 0;
  tiles.addEventListener("load-error", (e) => fail(`${e.url}: ${e.error?.message ?? e.error}`));
  tiles.addEventListener("load-root-tileset", ({ tileset }) => {
    const root = tileset.root;
    const box = root.boundingVolume?.box;
    if (!box) {
      fail("the root tile has no box bounding volume (dbms writes boxes)");
      return;
    }
    // Back from ECEF to the local frame, then z-up -> y-up (a -90° turn about x).
    const local = new THREE.Matrix4();
    if (root.transform) local.fromArray(root.transform).invert();
    const yUp = new THREE.Matrix4().makeRotationX(-Math.PI / 2);
    tiles.group.matrixAutoUpdate = false;
    tiles.group.matrix.multiplyMatrices(yUp, local);
    tiles.group.matrixWorldNeedsUpdate = true;

    const { centre, corners } = boxCorners(box);
    let eye = numbers("camera", 3, null);
    let target = numbers("target", 3, null);
    if (eye === null && target === null) [eye, target] = frameBox(camera, centre, corners);
    target ??= centre;
    eye ??= target.map((t, k) => t + fitDistance(camera, target, corners) * VIEW_DIR[k]);
    camera.position.copy(toThree(eye));
    camera.lookAt(toThree(target));
    const reach = Math.max(...corners.map((c) => Math.hypot(c[0] - eye[0], c[1] - eye[1], c[2] - eye[2])));
    camera.near = Math.max(0.1, reach / 5000);
    camera.far = reach * 1.5;
    camera.updateProjectionMatrix();
    placed = true;
  });

  renderer.setAnimationLoop(() => {
    camera.updateMatrixWorld();
    tiles.update();
    renderer.render(scene, camera);
    if (window.__dbmsReady || window.__dbmsError !== undefined || !placed) return;
    const { queued, downloading, parsing } = tiles.stats;
    // A view with nothing in it settles too, with no tiles: the screenshot script sees the sky.
    const busy = tiles.isLoading || queued + downloading + parsing > 0;
    settled = busy ? 0 : settled + 1;
    if (settled < SETTLE_FRAMES) return;
    let triangles = 0;
    tiles.group.traverseVisible((o) => {
      if (o.isMesh) triangles += (o.geometry.index ?? o.geometry.attributes.position).count / 3;
    });
    window.__dbmsReady = { tiles: tiles.visibleTiles.size, triangles };
  });
}

try {
  main();
} catch (e) {
  fail(e.message);
}
