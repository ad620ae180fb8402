// Prints, for a .glb written by hrad, one line per node and one per material:
//   node NAME AREA R G B      material NAME AREA R G B
// with the area-weighted mean of the _RADIOSITY attribute over its triangles (linear B, W/m^2),
// and a last line "max R G B" (largest _RADIOSITY per channel; "nan" if any value is not finite).
// Names are printed as JSON strings. Plain Node.js, no modules: the tests read the output glTF the
// way a user's pipeline would.
// usage: node tests/glb_objects.mjs FILE.glb
import { readFileSync } from 'node:fs';

const buf = readFileSync(process.argv[2]);
const dv = new DataView(buf.buffer, buf.byteOffset, buf.byteLength);
if (dv.getUint32(0, true) !== 0x46546c67) throw new Error('not a GLB');
const jlen = dv.getUint32(12, true);
const gltf = JSON.parse(buf.subarray(20, 20 + jlen).toString('utf8'));
const binStart = 20 + jlen + 8;

function accessor(i) {
  const a = gltf.accessors[i], v = gltf.bufferViews[a.bufferView];
  const n = a.type === 'VEC3' ? 3 : 1, stride = v.byteStride || 4 * n;
  const off = binStart + (v.byteOffset || 0) + (a.byteOffset || 0);
  const out = [];
  for (let k = 0; k < a.count; k++)
    for (let c = 0; c < n; c++) {
      const p = off + k * stride + 4 * c;
      out.push(a.componentType === 5125 ? dv.getUint32(p, true) : dv.getFloat32(p, true));
    }
  return out;
}

const sums = new Map();
const add = (key, a, b) => {
  const s = sums.get(key) || [0, 0, 0, 0];
  s[0] += a;
  for (let c = 0; c < 3; c++) s[c + 1] += a * b[c];
  sums.set(key, s);
};
const max = [-Infinity, -Infinity, -Infinity];
let finite = true;
for (const node of gltf.nodes) {
  for (const prim of gltf.meshes[node.mesh].primitives) {
    const P = accessor(prim.attributes.POSITION), R = accessor(prim.attributes._RADIOSITY);
    const I = accessor(prim.indices);
    for (let k = 0; k < R.length; k++) {
      if (!Number.isFinite(R[k])) finite = false;
      max[k % 3] = Math.max(max[k % 3], R[k]);
    }
    for (let t = 0; t < I.length; t += 3) {
      const [a, b, c] = [I[t], I[t + 1], I[t + 2]];
      const e1 = [0, 1, 2].map((j) => P[3 * b + j] - P[3 * a + j]);
      const e2 = [0, 1, 2].map((j) => P[3 * c + j] - P[3 * a + j]);
      const x = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                 e1[0] * e2[1] - e1[1] * e2[0]];
      const area = 0.5 * Math.hypot(...x);
      const B = [0, 1, 2].map((j) => (R[3 * a + j] + R[3 * b + j] + R[3 * c + j]) / 3);
      add('node ' + JSON.stringify(node.name), area, B);
      add('material ' + JSON.stringify(gltf.materials[prim.material].name), area, B);
    }
  }
}
for (const [key, s] of sums)
  console.log(`${key} ${s[0].toPrecision(6)} ` +
              [1, 2, 3].map((c) => (s[c] / s[0]).toPrecision(7)).join(' '));
console.log(finite ? `max ${max.map((x) => x.toPrecision(7)).join(' ')}` : 'max nan nan nan');
