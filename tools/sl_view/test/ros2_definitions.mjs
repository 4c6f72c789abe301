// ROS 2 interface packages read as Foxglove's ROS 2 (de)serializer takes
// them: each .msg and each .srv half parsed (@foxglove/rosmsg) together with
// every type it uses, from the package's own .msg files or else the standard
// ROS 2 (Humble) definitions of @foxglove/rosmsg-msgs-common.
import fs from 'node:fs';
import path from 'node:path';
import { parse, stringify } from '@foxglove/rosmsg';
import { ros2humble } from '@foxglove/rosmsg-msgs-common';

const SEPARATOR = '='.repeat(80);

// { pkg, types: [[wire name "pkg/msg/Type" | "pkg/srv/Type_Request", definitions]] }
export function loadPackage(packageDir) {
  const pkg = path.basename(path.resolve(packageDir));
  const ownText = new Map();
  const msgDir = path.join(packageDir, 'msg');
  if (fs.existsSync(msgDir))
    for (const file of fs.readdirSync(msgDir))
      ownText.set(`${pkg}/${path.basename(file, '.msg')}`, fs.readFileSync(path.join(msgDir, file), 'utf8'));
  const textOf = (type) => {
    if (ownText.has(type)) return ownText.get(type);
    if (ros2humble[type]) return stringify([ros2humble[type]]);
    throw new Error(`no definition of ${type}`);
  };
  const usedTypes = (text) => text.split('\n').map((l) => l.replace(/#.*/, '').trim().split(/\s+/)[0] ?? '')
    .map((t) => t.replace(/\[.*$/, '')).filter((t) => t.includes('/'));
  const definitionsOf = (text) => {
    const sections = [text], seen = new Set();
    for (let i = 0; i < sections.length; i++)
      for (const t of usedTypes(sections[i]))
        if (!seen.has(t)) { seen.add(t); sections.push(`MSG: ${t}\n${textOf(t)}`); }
    return parse(sections.join(`\n${SEPARATOR}\n`), { ros2: true });
  };
  const types = [];
  for (const kind of ['msg', 'srv']) {
    const dir = path.join(packageDir, kind);
    if (!fs.existsSync(dir)) continue;
    for (const file of fs.readdirSync(dir).sort()) {
      const text = fs.readFileSync(path.join(dir, file), 'utf8');
      const name = path.basename(file, `.${kind}`);
      if (kind === 'msg') {
        types.push([`${pkg}/msg/${name}`, definitionsOf(text)]);
      } else {
        const parts = text.split(/^---\s*$/m);
        if (parts.length !== 2) throw new Error(`${file}: not one '---' line`);
        types.push([`${pkg}/srv/${name}_Request`, definitionsOf(parts[0])]);
        types.push([`${pkg}/srv/${name}_Response`, definitionsOf(parts[1])]);
      }
    }
  }
  return { pkg, types, get: (wireName) => types.find(([n]) => n === wireName)?.[1] };
}
