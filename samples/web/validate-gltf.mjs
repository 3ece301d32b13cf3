// Validate every .glb under a directory with the Khronos glTF validator.
//
//   node validate-gltf.mjs DIR
//
// Prints one line per file (sorted paths, recursively) with its error, warning and info
// counts, and the message of every error and warning under it. Exits 1 when a file has an
// error or a warning, or when DIR holds no .glb or cannot be read; 0 otherwise (2 for a
// wrong command line). dbms writes files with neither (see src/lib/mesh/gltf.rs), so a
// warning is a regression too. Infos (an unused object, a degenerate triangle) are counted,
// not failed.

import { readdir, readFile } from "node:fs/promises";
import path from "node:path";
import process from "node:process";
import { validateBytes } from "gltf-validator";

/** Every .glb file under `dir`, sorted. */
async function glbFiles(dir) {
  const entries = await readdir(dir, { recursive: true, withFileTypes: true });
  return entries
    .filter((e) => e.isFile() && e.name.toLowerCase().endsWith(".glb"))
    .map((e) => path.join(e.parentPath ?? e.path, e.name))
    .sort();
}

async function main() {
  const args = process.argv.slice(2);
  if (args.length !== 1) {
    console.error("usage: node validate-gltf.mjs DIR");
    return 2;
  }
  const dir = args[0];
  let files;
  try {
    files = await glbFiles(dir);
  } catch (e) {
    console.error(`${dir}: ${e.message}`);
    return 1;
  }
  if (files.length === 0) {
    console.error(`${dir}: no .glb file found`);
    return 1;
  }
  let failed = 0;
  for (const file of files) {
    const name = path.relative(dir, file);
    let report;
    try {
      report = await validateBytes(new Uint8Array(await readFile(file)), {
        uri: name,
        maxIssues: 0, // every issue, not the first 100
        writeTimestamp: false,
      });
    } catch (e) {
      // A rejection: the validator could not even tell glTF from GLB.
      console.log(`${name}: FAIL (not validated: ${e})`);
      failed++;
      continue;
    }
    const { numErrors, numWarnings, numInfos, messages } = report.issues;
    const bad = numErrors > 0 || numWarnings > 0;
    failed += bad ? 1 : 0;
    console.log(
      `${name}: ${bad ? "FAIL" : "ok"} (${numErrors} errors, ${numWarnings} warnings, ${numInfos} infos)`,
    );
    // Severity: 0 error, 1 warning, 2 info, 3 hint.
    for (const m of messages.filter((m) => m.severity <= 1)) {
      const kind = m.severity === 0 ? "error" : "warning";
      console.log(`  ${kind} ${m.code} at ${m.pointer ?? m.offset ?? "?"}: ${m.message}`);
    }
  }
  console.log(`${files.length} files, ${failed} failed`);
  return failed > 0 ? 1 : 0;
}

process.exitCode = await main();
