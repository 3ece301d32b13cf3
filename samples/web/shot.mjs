// Screenshot a `dbms export mesh` tileset in viewer.html with headless Chromium.
//
//   node shot.mjs TILESET_DIR OUT.png [WIDTH HEIGHT [QUERY]]
//
// Serves this directory (the page, its module and node_modules) and TILESET_DIR (under /out/)
// over HTTP on 127.0.0.1 at a free port, opens viewer.html?tileset=/out/tileset.json (plus
// QUERY, e.g. "camera=-300,-300,250&fov=30": viewer.js lists the parameters) at WIDTH×HEIGHT
// (default 1280×800) in the system Chromium (/usr/bin/chromium, or $CHROMIUM) driven by
// playwright-core, which never downloads a browser and gives every run a fresh profile (a
// temporary user-data-dir, removed on close). Without a GPU, WebGL runs on SwiftShader.
//
// Waits (up to 120 s) for the page to say every tile it wants has loaded, then writes OUT.png
// and prints the tiles and triangles drawn. Exits 1, writing nothing, on a page error, a
// console error, a failed or refused request (e.g. a 404), a load error the viewer reports,
// a timeout, or a picture that is one flat colour or nearly all sky; 2 on a wrong command
// line.

import http from "node:http";
import { createReadStream } from "node:fs";
import { stat, writeFile } from "node:fs/promises";
import path from "node:path";
import process from "node:process";
import { fileURLToPath } from "node:url";
import { chromium } from "playwright-core";

const HERE = path.dirname(fileURLToPath(import.meta.url));
const TIMEOUT_MS = 120_000;
const CHROMIUM_ARGS = [
  "--headless",
  "--no-sandbox",
  "--disable-gpu",
  "--disable-quic",
  "--no-first-run",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  // WebGL on the CPU: Chromium no longer falls back to SwiftShader by itself.
  "--use-angle=swiftshader",
  "--enable-unsafe-swiftshader",
];
const TYPES = {
  ".html": "text/html; charset=utf-8",
  ".js": "text/javascript; charset=utf-8",
  ".mjs": "text/javascript; charset=utf-8",
  ".json": "application/json",
  ".glb": "model/gltf-binary",
  ".bin": "application/octet-stream",
  ".png": "image/png",
  ".map": "application/json",
};
/** At least this share of the picture in one colour (the sky) means nothing is in view. */
const MAX_FLAT_SHARE = 0.98;

/** A file server for `roots` (URL prefix -> directory), GET and HEAD only, nothing outside. */
function server(roots) {
  return http.createServer(async (req, res) => {
    const reply = (code, text) => {
      res.writeHead(code, { "content-type": "text/plain" });
      res.end(text);
    };
    if (req.method !== "GET" && req.method !== "HEAD") return reply(405, "GET or HEAD only\n");
    let pathname;
    try {
      pathname = decodeURIComponent(new URL(req.url, "http://localhost").pathname);
    } catch {
      return reply(400, "bad URL\n");
    }
    const [prefix, dir] = Object.entries(roots).find(([p]) => pathname.startsWith(p));
    const file = path.resolve(dir, "." + pathname.slice(prefix.length - 1));
    if (file !== dir && !file.startsWith(dir + path.sep)) return reply(403, "outside the served tree\n");
    let info;
    try {
      info = await stat(file);
    } catch {
      return reply(404, `not found: ${pathname}\n`);
    }
    if (!info.isFile()) return reply(404, `not a file: ${pathname}\n`);
    res.writeHead(200, {
      "content-type": TYPES[path.extname(file).toLowerCase()] ?? "application/octet-stream",
      "content-length": info.size,
      "cache-control": "no-store",
    });
    if (req.method === "HEAD") return res.end();
    createReadStream(file).pipe(res);
  });
}

/**
 * In the page: how flat the PNG is, as the share of its most common colour and the number of
 * distinct colours.
 */
async function flatness(page, png) {
  return page.evaluate(async (b64) => {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const bitmap = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
    const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
    const ctx = canvas.getContext("2d");
    ctx.drawImage(bitmap, 0, 0);
    const data = new Uint32Array(ctx.getImageData(0, 0, bitmap.width, bitmap.height).data.buffer);
    const counts = new Map();
    for (const v of data) counts.set(v, (counts.get(v) ?? 0) + 1);
    return { share: Math.max(...counts.values()) / data.length, colours: counts.size };
  }, png.toString("base64"));
}

async function main() {
  const args = process.argv.slice(2);
  if (![2, 4, 5].includes(args.length)) {
    console.error("usage: node shot.mjs TILESET_DIR OUT.png [WIDTH HEIGHT [QUERY]]");
    return 2;
  }
  const [tilesetDir, out, w = "1280", h = "800", query = ""] = args;
  const [width, height] = [Number(w), Number(h)];
  if (!Number.isInteger(width) || !Number.isInteger(height) || width < 16 || height < 16) {
    console.error(`shot.mjs: WIDTH and HEIGHT must be integers of at least 16, not ${w} ${h}`);
    return 2;
  }
  const tilesetRoot = path.resolve(tilesetDir);
  try {
    await stat(path.join(tilesetRoot, "tileset.json"));
  } catch (e) {
    console.error(`shot.mjs: ${tilesetDir}: no tileset.json (${e.code})`);
    return 1;
  }

  // Longest prefix first: /out/ before /.
  const files = server({ "/out/": tilesetRoot, "/": HERE });
  await new Promise((ok) => files.listen(0, "127.0.0.1", ok));
  const origin = `http://127.0.0.1:${files.address().port}`;
  const problems = [];
  let browser;
  try {
    browser = await chromium.launch({
      executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
      args: CHROMIUM_ARGS,
      timeout: 60_000,
    });
    const page = await browser.newPage({ viewport: { width, height } });
    page.on("pageerror", (e) => problems.push(`page error: ${e.message}`));
    page.on("console", (m) => m.type() === "error" && problems.push(`console error: ${m.text()}`));
    page.on("requestfailed", (r) => problems.push(`request failed: ${r.url()} (${r.failure()?.errorText})`));
    page.on("response", (r) => r.status() >= 400 && problems.push(`HTTP ${r.status()}: ${r.url()}`));

    const url = `${origin}/viewer.html?tileset=/out/tileset.json${query ? "&" + query : ""}`;
    const started = Date.now();
    await page.goto(url);
    const state = await page
      .waitForFunction(() => window.__dbmsReady ?? (window.__dbmsError !== undefined || null), null, {
        timeout: TIMEOUT_MS,
        polling: 250,
      })
      .then(() => page.evaluate(() => ({ ready: window.__dbmsReady, error: window.__dbmsError })))
      .catch((e) => ({ error: `no picture within ${TIMEOUT_MS / 1000} s (${e.message.split("\n")[0]})` }));
    const seconds = ((Date.now() - started) / 1000).toFixed(1);
    if (state.error !== undefined) problems.push(`viewer: ${state.error}`);
    if (problems.length > 0) throw new Error(problems.join("\n"));

    const png = await page.screenshot({ type: "png" });
    const flat = await flatness(page, png);
    if (flat.share >= MAX_FLAT_SHARE) {
      throw new Error(
        `the picture is ${(flat.share * 100).toFixed(1)} % one colour (${flat.colours} colours): nothing in view`,
      );
    }
    if (problems.length > 0) throw new Error(problems.join("\n"));
    await writeFile(out, png);
    const { tiles, triangles } = state.ready;
    console.log(`${out}: ${width}×${height}, ${tiles} tiles, ${triangles} triangles drawn, ready in ${seconds} s`);
    return 0;
  } catch (e) {
    console.error(`shot.mjs: ${e.message}`);
    return 1;
  } finally {
    await browser?.close();
    await new Promise((ok) => files.close(ok));
  }
}

process.exitCode = await main();
