#!/usr/bin/env bash
# `cmake --install` installs sl_view with its page and three.js, and the
# installed sl_view serves them from there (not from the source tree).
# usage: install_test.sh SOURCE_DIR BINARY_DIR
set -euo pipefail
src=$1
bin=$2
export CYCLONEDDS_URI=${CYCLONEDDS_URI:-file://$src/config/cyclonedds-loopback.xml}
work=$(mktemp -d)
view_pid=
cleanup() { [ -n "$view_pid" ] && kill "$view_pid" 2>/dev/null; rm -rf "$work"; }
trap cleanup EXIT
fail() { echo "FAIL: $*" >&2; [ -f "$work/view.log" ] && cat "$work/view.log" >&2; exit 1; }

DESTDIR="$work/root" cmake --install "$bin" --prefix /usr > "$work/install.log" || fail "cmake --install"
root="$work/root/usr"
[ -x "$root/bin/sl_view" ] || fail "no bin/sl_view installed"
"$root/bin/sl_view" --ns "install_$$" --port 0 > "$work/view.log" 2>&1 &
view_pid=$!
for _ in $(seq 100); do grep -q "live view at" "$work/view.log" && break; sleep 0.1; done
port=$(grep -o "http://127.0.0.1:[0-9]*" "$work/view.log" | grep -o "[0-9]*$") || fail "sl_view did not start"
! grep -q "three.module.js not found" "$work/view.log" || fail "the installed sl_view did not find three.js"
# Each file the page loads, byte for byte as in the source tree / npm package.
check() {  # URL_PATH SOURCE_FILE
  node -e '
    const [url, file] = process.argv.slice(1);
    fetch(url).then(async (r) => {
      const body = Buffer.from(await r.arrayBuffer());
      if (r.status !== 200) throw new Error(`${url}: HTTP ${r.status}`);
      if (!body.equals(require("fs").readFileSync(file))) throw new Error(`${url} differs from ${file}`);
    }).catch((e) => { console.error(e.message); process.exit(1); });' \
    "http://127.0.0.1:$port$1" "$2" || fail "GET $1"
}
check / "$src/tools/sl_view/web/index.html"
check /app.js "$src/tools/sl_view/web/app.js"
check /style.css "$src/tools/sl_view/web/style.css"
three=$src/tools/sl_view/node_modules/three
check /three/build/three.module.js "$three/build/three.module.js"
check /three/build/three.core.js "$three/build/three.core.js"
check /three/examples/jsm/controls/OrbitControls.js "$three/examples/jsm/controls/OrbitControls.js"
# Served from the installed copy, not from the source tree: a change to the
# installed file is what the page gets.
echo "/* installed copy */" >> "$root/share/sl-sensor/sl_view/web/style.css"
check /style.css "$root/share/sl-sensor/sl_view/web/style.css"
echo "ok: installed sl_view serves its page and three.js from $root/share/sl-sensor/sl_view"
