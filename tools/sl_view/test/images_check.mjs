// The daemon's images as image_transport and depth_image_proc take them
// (issue 31 item 6), checked from raw samples (tests/ros2/raw_topic_dump)
// decoded by Foxglove's ROS 2 deserializer with the standard (Humble)
// definitions, not with the project's types:
// - depth/image_rect (32FC1, m) and its sibling depth/camera_info (D = 0,
//   R = I, P = [K | 0], same size, frame and stamp): rebuilding the points as
//   depth_image_proc's convertDepth does (image_pipeline,
//   depth_image_proc/include/depth_image_proc/depth_conversions.hpp: float
//   center_x = P[2], constant_x = 1 / P[0]; x = (u - center_x) * depth *
//   constant_x, y likewise with P[6], P[5]; z = depth) gives points on the
//   surface of /points: each one's ray, distorted with the raw camera's
//   plumb_bob model (camera_info: D, K), meets the raw grid where /points,
//   interpolated bilinearly, lies on that ray (lateral error) at that depth;
// - the same measure for the raw depth/image with the raw camera_info's P,
//   the way depth_image_proc would have used it before (printed: old vs new);
// - shading/image/compressed (image_transport's compressed, png) decodes to
//   shading/image exactly, and depth/image_rect/compressedDepth
//   (compressed_depth_image_transport, png: 12-byte ConfigHeader {int32
//   INV_DEPTH, float A, float B}, then a 16-bit PNG of q = A / z + B) to
//   depth/image_rect within its quantization step, NaN where it is NaN. The
//   PNGs are decoded here (node's zlib and PNG's filters), not by OpenCV,
//   which encoded them.
//   node images_check.mjs DIR   (DIR: points_1.cdr, rect_1.cdr, rect_info_1.cdr,
//                                raw_1.cdr, raw_info_1.cdr, shading_info_1.cdr,
//                                shading_1.cdr, shading_png_1.cdr, depth_png_1.cdr)
import fs from 'node:fs';
import zlib from 'node:zlib';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { ros2humble } from '@foxglove/rosmsg-msgs-common';

const dir = process.argv[2];
let failures = 0;
const check = (c, what) => { if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };

function readerOf(type) {  // root first, then every type it uses
  const out = [];
  const visit = (name) => {
    if (out.some((d) => d.name === name)) return;
    const def = ros2humble[name];
    if (!def) throw new Error(`no standard definition of ${name}`);
    out.push(def);
    for (const f of def.definitions) if (f.isComplex) visit(f.type);
  };
  visit(type);
  return new MessageReader(out);
}
const decode = (type, file) => readerOf(type).readMessage(fs.readFileSync(`${dir}/${file}`));
const cloud = decode('sensor_msgs/PointCloud2', 'points_1.cdr');
const rect = decode('sensor_msgs/Image', 'rect_1.cdr');
const rectInfo = decode('sensor_msgs/CameraInfo', 'rect_info_1.cdr');
const raw = decode('sensor_msgs/Image', 'raw_1.cdr');
const rawInfo = decode('sensor_msgs/CameraInfo', 'raw_info_1.cdr');
const shadingInfo = decode('sensor_msgs/CameraInfo', 'shading_info_1.cdr');

// --- one scan, one frame --------------------------------------------------------------
const stampOf = (m) => `${m.header.stamp.sec}.${m.header.stamp.nanosec}`;
for (const [name, m] of Object.entries({ rect, rectInfo, raw, rawInfo, shadingInfo })) {
  check(stampOf(m) === stampOf(cloud), `${name} stamp ${stampOf(m)} is the cloud's ${stampOf(cloud)}`);
  check(m.header.frame_id === cloud.header.frame_id, `${name} frame '${m.header.frame_id}' is the cloud's`);
}
const W = cloud.width, H = cloud.height;
for (const [name, m] of Object.entries({ rect, raw, rectInfo, rawInfo }))
  check(m.width === W && m.height === H, `${name} is ${m.width}x${m.height}, the cloud ${W}x${H}`);
for (const [name, m] of Object.entries({ rect, raw })) {
  check(m.encoding === '32FC1' && m.is_bigendian === 0 && m.step === 4 * W,
    `${name}: encoding ${m.encoding}, is_bigendian ${m.is_bigendian}, step ${m.step}`);
}

// --- the camera_infos ----------------------------------------------------------------
const same = (a, b) => a.length === b.length && a.every((v, i) => v === b[i]);
const I3 = [1, 0, 0, 0, 1, 0, 0, 0, 1];
const Krect = Array.from(rectInfo.k), Prect = Array.from(rectInfo.p);
check(rectInfo.distortion_model === 'plumb_bob' && rectInfo.d.length === 5 && Array.from(rectInfo.d).every((d) => d === 0),
  `depth/camera_info: D = 0 (plumb_bob), got ${rectInfo.distortion_model} [${Array.from(rectInfo.d)}]`);
check(same(Array.from(rectInfo.r), I3), 'depth/camera_info: R = I');
check(same(Prect, [Krect[0], 0, Krect[2], 0, 0, Krect[4], Krect[5], 0, 0, 0, 1, 0]), `depth/camera_info: P = [K | 0], P = [${Prect}]`);
const D = Array.from(rawInfo.d), Kraw = Array.from(rawInfo.k);
check(rawInfo.distortion_model === 'plumb_bob' && D.length === 5 && D.some((d) => d !== 0),
  `raw camera_info: the lens's plumb_bob distortion (the simulated camera has one), got [${D}]`);
check(same(Array.from(shadingInfo.d), D) && same(Array.from(shadingInfo.k), Kraw) && same(Array.from(shadingInfo.p), Array.from(rawInfo.p)),
  'shading/camera_info is the raw camera_info');

// --- /points ---------------------------------------------------------------------------
const field = (n) => cloud.fields.find((f) => f.name === n);
check(['x', 'y', 'z'].every((n) => field(n) && field(n).datatype === 7), 'cloud has float32 x, y, z');
const cdv = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
const at = (u, v) => {
  const o = v * cloud.row_step + u * cloud.point_step;
  return [cdv.getFloat32(o + field('x').offset, true), cdv.getFloat32(o + field('y').offset, true),
    cdv.getFloat32(o + field('z').offset, true)];
};
// /points bilinearly at raw pixel (su, sv); null unless its 4 points are valid.
function pointsAt(su, sv) {
  const u0 = Math.floor(su), v0 = Math.floor(sv);
  if (!(u0 >= 0 && v0 >= 0 && u0 + 1 < W && v0 + 1 < H)) return null;
  const a = su - u0, b = sv - v0;
  const p = [at(u0, v0), at(u0 + 1, v0), at(u0, v0 + 1), at(u0 + 1, v0 + 1)];
  if (p.some((q) => !q.every(Number.isFinite))) return null;
  const w = [(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b];
  return [0, 1, 2].map((k) => w[0] * p[0][k] + w[1] * p[1][k] + w[2] * p[2][k] + w[3] * p[3][k]);
}
// The raw camera's plumb_bob model: normalized undistorted -> raw pixel.
function distortToPixel(x, y) {
  const [k1, k2, p1, p2, k3] = D;
  const r2 = x * x + y * y, radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3));
  const xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x);
  const yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y;
  return [Kraw[0] * xd + Kraw[1] * yd + Kraw[2], Kraw[4] * yd + Kraw[5]];
}

// depth_image_proc's convertDepth for 32FC1 (float arithmetic as there).
function convertDepth(image, P) {
  const f = Math.fround;
  const centerX = f(P[2]), centerY = f(P[6]), constantX = f(1 / P[0]), constantY = f(1 / P[5]);
  const dv = new DataView(image.data.buffer, image.data.byteOffset, image.data.byteLength);
  const out = [];
  for (let v = 0; v < image.height; v++)
    for (let u = 0; u < image.width; u++) {
      const depth = dv.getFloat32(v * image.step + 4 * u, true);
      if (!Number.isFinite(depth)) continue;
      out.push([u, v, f(f(f(u - centerX) * depth) * constantX), f(f(f(v - centerY) * depth) * constantY), depth]);
    }
  return out;
}
const quantile = (xs, q) => xs[Math.min(xs.length - 1, Math.floor(q * xs.length))];
function errors(points, referenceOf) {
  const lateral = [], depth = [];
  let unmatched = 0;
  for (const [u, v, x, y, z] of points) {
    const q = referenceOf(u, v, x, y, z);
    if (!q) { unmatched++; continue; }
    // q's distance from the ray through (x, y, z), and the depth difference.
    const n = Math.hypot(x, y, z), r = [x / n, y / n, z / n];
    const along = q[0] * r[0] + q[1] * r[1] + q[2] * r[2];
    lateral.push(Math.hypot(q[0] - along * r[0], q[1] - along * r[1], q[2] - along * r[2]));
    depth.push(Math.abs(q[2] - z));
  }
  lateral.sort((a, b) => a - b);
  depth.sort((a, b) => a - b);
  return { lateral, depth, unmatched };
}
const mm = (m) => (m * 1e3).toFixed(5);
const summary = (e) => `lateral median ${mm(quantile(e.lateral, 0.5))} mm, p95 ${mm(quantile(e.lateral, 0.95))} mm, ` +
  `max ${mm(e.lateral[e.lateral.length - 1])} mm; depth max ${mm(e.depth[e.depth.length - 1])} mm ` +
  `(${e.lateral.length} pixels, ${e.unmatched} without 4 valid neighbours in /points)`;

// Old: the raw grid with the raw camera_info's P, compared pixel for pixel.
const old = errors(convertDepth(raw, Array.from(rawInfo.p)), (u, v) => {
  const q = at(u, v);
  return q.every(Number.isFinite) ? q : null;
});
console.log(`raw depth/image + camera_info (P = K): ${summary(old)}`);
// New: the rectified grid with its sibling camera_info.
const rebuilt = convertDepth(rect, Prect);
const fresh = errors(rebuilt, (u, v, x, y, z) => pointsAt(...distortToPixel(x / z, y / z)));
console.log(`depth/image_rect + depth/camera_info: ${summary(fresh)}`);

let validCloud = 0;
for (let v = 0; v < H; v++) for (let u = 0; u < W; u++) if (at(u, v).every(Number.isFinite)) validCloud++;
console.log(`valid pixels: /points ${validCloud}, depth/image_rect ${rebuilt.length}`);
check(rebuilt.length >= 0.95 * validCloud, `depth/image_rect has ${rebuilt.length} valid pixels, /points ${validCloud}`);
check(fresh.unmatched <= 0.001 * rebuilt.length, `${fresh.unmatched} rectified pixels fall where /points has no 4 valid neighbours`);
check(fresh.lateral[fresh.lateral.length - 1] < 1e-5, `lateral error max ${mm(fresh.lateral[fresh.lateral.length - 1])} mm >= 0.01 mm`);
check(fresh.depth[fresh.depth.length - 1] < 1e-5, `depth error max ${mm(fresh.depth[fresh.depth.length - 1])} mm >= 0.01 mm`);
// The measure itself sees the lens: the raw grid read as rectified is off.
check(quantile(old.lateral, 0.5) > 100 * quantile(fresh.lateral, 0.5), 'the raw grid is measurably off (the check has teeth)');

// --- compressed siblings -----------------------------------------------------------
// A PNG of 8- or 16-bit grey, non-interlaced -> { width, height, depth, pixels[] }.
function decodePng(bytes) {
  const sig = [137, 80, 78, 71, 13, 10, 26, 10];
  if (!sig.every((b, i) => bytes[i] === b)) throw new Error('not a PNG');
  let width = 0, height = 0, depth = 0, colour = 0, interlace = 0;
  const idat = [];
  for (let o = 8; o < bytes.length;) {
    const len = bytes.readUInt32BE(o), type = bytes.toString('latin1', o + 4, o + 8);
    const body = bytes.subarray(o + 8, o + 8 + len);
    if (type === 'IHDR') {
      width = body.readUInt32BE(0); height = body.readUInt32BE(4);
      depth = body[8]; colour = body[9]; interlace = body[12];
    } else if (type === 'IDAT') idat.push(body);
    o += 12 + len;
  }
  if (colour !== 0 || interlace !== 0 || (depth !== 8 && depth !== 16))
    throw new Error(`PNG colour type ${colour}, depth ${depth}, interlace ${interlace}: not plain grey`);
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const bpp = depth / 8, stride = width * bpp;
  const out = Buffer.alloc(stride * height);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)], line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= bpp ? out[y * stride + x - bpp] : 0, b = y > 0 ? out[(y - 1) * stride + x] : 0;
      const c = x >= bpp && y > 0 ? out[(y - 1) * stride + x - bpp] : 0;
      let p;
      switch (filter) {
        case 0: p = 0; break;
        case 1: p = a; break;
        case 2: p = b; break;
        case 3: p = (a + b) >> 1; break;
        case 4: { const q = a + b - c, pa = Math.abs(q - a), pb = Math.abs(q - b), pc = Math.abs(q - c);
          p = pa <= pb && pa <= pc ? a : pb <= pc ? b : c; break; }
        default: throw new Error(`PNG filter ${filter}`);
      }
      out[y * stride + x] = (line[x] + p) & 255;
    }
  }
  const pixels = depth === 8 ? Array.from(out) : Array.from({ length: width * height }, (_, i) => out.readUInt16BE(2 * i));
  return { width, height, depth, pixels };
}
const shading = decode('sensor_msgs/Image', 'shading_1.cdr');
const shadingPng = decode('sensor_msgs/CompressedImage', 'shading_png_1.cdr');
const depthPng = decode('sensor_msgs/CompressedImage', 'depth_png_1.cdr');
for (const [name, m] of Object.entries({ shadingPng, depthPng })) {
  check(stampOf(m) === stampOf(cloud) && m.header.frame_id === cloud.header.frame_id, `${name}: the cloud's stamp and frame`);
}
check(shadingPng.format === 'mono8; png compressed ', `shading/image/compressed format '${shadingPng.format}'`);
const sp = decodePng(Buffer.from(shadingPng.data));
check(sp.width === shading.width && sp.height === shading.height && sp.depth === 8, `shading PNG ${sp.width}x${sp.height}, ${sp.depth} bit`);
let shadingDiff = 0;
for (let i = 0; i < sp.pixels.length; i++) shadingDiff += sp.pixels[i] !== shading.data[i];
check(shadingDiff === 0, `${shadingDiff} shading pixels differ after PNG`);
console.log(`shading/image/compressed: ${shadingPng.data.length} bytes for ${shading.data.length} (${(shading.data.length / shadingPng.data.length).toFixed(1)}:1), pixel for pixel equal`);

check(depthPng.format === '32FC1; compressedDepth png', `compressedDepth format '${depthPng.format}'`);
const cd = Buffer.from(depthPng.data);
const [kind, A, B] = [cd.readInt32LE(0), cd.readFloatLE(4), cd.readFloatLE(8)];
check(kind === 0, `ConfigHeader format ${kind}, INV_DEPTH (0) expected`);
const dp = decodePng(cd.subarray(12));
check(dp.width === W && dp.height === H && dp.depth === 16, `compressedDepth PNG ${dp.width}x${dp.height}, ${dp.depth} bit`);
const rdv = new DataView(rect.data.buffer, rect.data.byteOffset, rect.data.byteLength);
let depthWorst = 0, depthNanMismatch = 0, depthCompared = 0;
for (let i = 0; i < W * H; i++) {
  const z = rdv.getFloat32(4 * i, true), q = dp.pixels[i];
  const got = q ? Math.fround(A / Math.fround(q - B)) : NaN;
  if (Number.isNaN(z) || Number.isNaN(got)) { depthNanMismatch += Number.isNaN(z) !== Number.isNaN(got); continue; }
  // One quantization step at z: dz = z^2 / A (q = A / z + B truncated).
  depthWorst = Math.max(depthWorst, Math.abs(got - z) / (z * z / A));
  depthCompared++;
}
console.log(`depth/image_rect/compressedDepth: ${cd.length} bytes for ${rect.data.length} (${(rect.data.length / cd.length).toFixed(1)}:1), ` +
  `A ${A}, B ${B}, ${depthCompared} depths within ${depthWorst.toFixed(3)} quantization steps`);
check(depthCompared === rebuilt.length, `${depthCompared} depths decoded, depth/image_rect has ${rebuilt.length}`);
check(depthNanMismatch === 0, `${depthNanMismatch} pixels NaN in one of compressedDepth and depth/image_rect only`);
check(depthWorst <= 1.001, `a compressedDepth depth is ${depthWorst} quantization steps off`);

if (failures) { console.error(`${failures} check(s) failed`); process.exit(1); }
console.log('ok: depth/image_rect with depth/camera_info rebuilds /points as depth_image_proc does; the compressed siblings decode to their images');
