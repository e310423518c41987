// Validates a .glb with the Khronos glTF validator and prints its report as JSON
// (tests/formats/test_formats.py reads it). Usage: node validate_gltf.js MESH.glb
const fs = require('fs');
const validator = require('gltf-validator');

validator.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])), {maxIssues: 20})
  .then((report) => process.stdout.write(JSON.stringify(report)))
  .catch((error) => { console.error(error); process.exit(1); });
