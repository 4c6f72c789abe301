// slctl's scan files as the Point Cloud Library reads them (issue 31 item 7),
// against the cloud the daemon published on /points for the same scan
// (a raw sample, decoded by Foxglove's ROS 2 deserializer):
//   node files_check.mjs ply POINTS.cdr PCL_ASCII.pcd   a PLY written by default
//     (metres) and converted by PCL (pcl_ply2pcd, pcl_convert_pcd_ascii_binary):
//     the finite points of /points in row-major order, x y z in metres
//   node files_check.mjs pcd-mm POINTS.cdr PCL_ASCII.pcd  a PCD written with
//     --units mm, read by PCL: organized width x height, millimetres, NaN kept
import fs from 'node:fs';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { ros2humble } from '@foxglove/rosmsg-msgs-common';

const [mode, pointsFile, pcdFile] = process.argv.slice(2);
let failures = 0;
const check = (c, what) => { if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };

const defs = [];
const visit = (name) => {
  if (defs.some((d) => d.name === name)) return;
  defs.push(ros2humble[name]);
  for (const f of ros2humble[name].definitions) if (f.isComplex) visit(f.type);
};
visit('sensor_msgs/PointCloud2');
const cloud = new MessageReader(defs).readMessage(fs.readFileSync(pointsFile));
const offset = Object.fromEntries(cloud.fields.map((f) => [f.name, f.offset]));
const dv = new DataView(cloud.data.buffer, cloud.data.byteOffset, cloud.data.byteLength);
const W = cloud.width, H = cloud.height;
const point = (i) => {
  const o = Math.floor(i / W) * cloud.row_step + (i % W) * cloud.point_step;
  return ['x', 'y', 'z', 'intensity'].map((n) => dv.getFloat32(o + offset[n], true));
};

// An ASCII PCD as PCL wrote it.
const text = fs.readFileSync(pcdFile, 'utf8');
const dataAt = text.indexOf('\nDATA ascii\n');
check(dataAt > 0, `${pcdFile}: no 'DATA ascii'`);
const header = Object.fromEntries(text.slice(0, dataAt).split('\n').filter((l) => !l.startsWith('#'))
  .map((l) => { const [k, ...v] = l.trim().split(/\s+/); return [k, v]; }));
const rows = text.slice(dataAt + 12).split('\n').filter((l) => l.length > 0);
const fields = header.FIELDS;
const col = Object.fromEntries(['x', 'y', 'z', 'intensity'].map((n) => [n, fields.indexOf(n)]));
check(Object.values(col).every((c) => c >= 0), `PCL's fields ${fields} lack x y z intensity`);
const parse = (s) => (/nan/i.test(s) ? NaN : Number(s));

let worst = 0, compared = 0, nanMismatch = 0, intensityMismatch = 0;
const compare = (want, row, scale) => {
  const got = row.trim().split(/\s+/).map(parse);
  for (const [k, n] of ['x', 'y', 'z'].entries()) {
    const w = want[k] * scale, g = got[col[n]];
    if (Number.isNaN(w) || Number.isNaN(g)) { nanMismatch += Number.isNaN(w) !== Number.isNaN(g); continue; }
    worst = Math.max(worst, Math.abs(w - g) / scale);  // in metres
  }
  if (Number.isFinite(want[3]) && !(Math.abs(want[3] - got[col.intensity]) <= 1e-3 * Math.max(1, Math.abs(want[3])))) intensityMismatch++;
  compared++;
};
const finite = [];
for (let i = 0; i < W * H; i++) if (Number.isFinite(point(i)[2])) finite.push(i);

if (mode === 'ply') {
  check(Number(header.WIDTH[0]) * Number(header.HEIGHT[0]) === finite.length && rows.length === finite.length,
    `PCL read ${header.WIDTH}x${header.HEIGHT} (${rows.length} rows) from the PLY, /points has ${finite.length} finite points`);
  for (let k = 0; k < Math.min(rows.length, finite.length); k++) compare(point(finite[k]), rows[k], 1);
} else if (mode === 'pcd-mm') {
  check(Number(header.WIDTH[0]) === W && Number(header.HEIGHT[0]) === H && rows.length === W * H,
    `PCL read ${header.WIDTH}x${header.HEIGHT} (${rows.length} rows), /points is ${W}x${H} (organized)`);
  for (let i = 0; i < Math.min(rows.length, W * H); i++) compare(point(i), rows[i], 1000);
} else {
  throw new Error(`unknown mode ${mode}`);
}
// PCL's ASCII keeps 8 significant digits: 1e-6 m on clouds within 10 m.
console.log(`${mode}: ${compared} points compared, largest x y z difference ${(worst * 1e3).toFixed(6)} mm, ${nanMismatch} NaN mismatches`);
check(compared > 0.5 * W * H, `only ${compared} points compared`);
check(worst < 1e-6, `a point differs by ${(worst * 1e3).toFixed(6)} mm (wrong unit?)`);
check(intensityMismatch === 0, `${intensityMismatch} intensities differ`);
check(nanMismatch === 0, `${nanMismatch} coordinates NaN in one and not the other`);
if (failures) { console.error(`${failures} check(s) failed`); process.exit(1); }
console.log(`ok: PCL reads the ${mode === 'ply' ? 'PLY in metres' : 'organized PCD in millimetres'} as /points`);
