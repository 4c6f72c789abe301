# Writes fuzz_recording's MCAP seeds (corpus/recording/mcap_{none,zstd,lz4}): "2" (the
# fuzzer's MCAP mode) + a small MCAP file of one image set (1 camera, 3 mono8 4x2
# images), its chunk uncompressed or compressed by the zstd / lz4 tools. A writer
# independent of tools/common/mcap_writer.cpp; test_replay reads the seeds back.
#   python3 fuzz/mcap_seeds.py fuzz/corpus/recording
import struct, sys, zlib, subprocess
def s(x): b = x.encode(); return struct.pack('<I', len(b)) + b
def rec(op, body): return struct.pack('<BQ', op, len(body)) + body
def cdr_set():
    out = bytearray(b'\x00\x01\x00\x00')
    def al(n):
        while (len(out) - 4) % n: out.append(0)
    def u32(v): al(4); out.extend(struct.pack('<I', v))
    def i32(v): al(4); out.extend(struct.pack('<i', v))
    def u64(v): al(8); out.extend(struct.pack('<Q', v))
    def st(x): u32(len(x) + 1); out.extend(x.encode() + b'\0')
    i32(1700000000); u32(5); st(''); st('p'); u64(7); u32(1)
    u32(1); st('cam'); u32(1); out.append(8)
    u32(3)
    for i in range(3):
        i32(1700000000); u32(5 + i * 1000); st('cam_optical_frame'); u32(2); u32(4); st('mono8')
        out.append(0); u32(4); u32(8); out.extend(bytes(range(i, i + 8)))
    return bytes(out)
def mcap(compression):
    schema = rec(3, struct.pack('<H', 1) + s('sl_msgs/msg/ImageSet') + s('ros2msg') + s('string pattern\n'))
    channel = rec(4, struct.pack('<HH', 1, 1) + s('/t/image_sets') + s('cdr') + struct.pack('<I', 0))
    msg = rec(5, struct.pack('<HIQQ', 1, 1, 5, 5) + cdr_set())
    records = schema + channel + msg
    data = records
    if compression == 'zstd': data = subprocess.run(['zstd', '-q', '-c'], input=records, capture_output=True, check=True).stdout
    if compression == 'lz4': data = subprocess.run(['lz4', '-q', '-c', '--content-size'], input=records, capture_output=True, check=True).stdout
    chunk = rec(6, struct.pack('<QQQI', 5, 5, len(records), zlib.crc32(records)) + s(compression) + struct.pack('<Q', len(data)) + data)
    magic = b'\x89MCAP0\r\n'
    body = magic + rec(1, s('ros2') + s('seed')) + chunk + rec(15, struct.pack('<I', 0))
    footer = rec(2, struct.pack('<QQI', 0, 0, 0))
    return body + footer + magic
for c in ['', 'zstd', 'lz4']:
    open(sys.argv[1] + '/mcap_' + (c or 'none'), 'wb').write(b'2' + mcap(c))
