// Validate glTF files with the Khronos glTF Validator.
// Usage: node .ci/validate.mjs FILE...
// Prints one JSON line per file: {"file", "errors", "warnings", "infos", "hints", "messages"}.
// Exit code 0 when every file has no errors and no warnings, 1 otherwise, 2 on usage errors.
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

const files = process.argv.slice(2);
if (files.length === 0) {
  console.error('usage: node .ci/validate.mjs FILE...');
  process.exit(2);
}
let bad = 0;
for (const file of files) {
  const data = new Uint8Array(await readFile(file));
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 100,
    externalResourceFunction: (uri) =>
      readFile(path.join(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  const i = report.issues;
  const messages = i.messages
    .filter((m) => m.severity <= 1)
    .map((m) => `${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer ?? ''}: ${m.message}`);
  console.log(JSON.stringify({ file, errors: i.numErrors, warnings: i.numWarnings, infos: i.numInfos, hints: i.numHints, messages }));
  if (i.numErrors > 0 || i.numWarnings > 0) bad += 1;
}
process.exit(bad > 0 ? 1 : 0);
