// Compiles every WGSL shader the SDK can create (`ksrt shaders --dump DIR`) in a real browser's
// WebGPU: Chromium's headless shell with SwiftShader (no GPU needed), through
// `createShaderModule` + `getCompilationInfo` and `createComputePipelineAsync` for each compute
// entry point with an automatic layout, on a device with WebGPU's default limits (the SDK's
// minimal configuration: `Features::empty()` + `Limits::default()`).
//
// The page posts each result back to this script's local server, so nothing depends on when the
// browser considers the page loaded (asynchronous WebGPU work outlives `--dump-dom`).
//
// Usage: node .ci/browser-shaders.mjs DIR [--browser PATH] [--timeout SECONDS]
//                                          [--skip-pipeline ENTRY]... [--modules-only TEXT]...
// Exit status: 0 when every shader compiles, 1 when one does not (each failure printed with the
// compiler's messages), 2 when the browser gives no WebGPU adapter or never reports.

import { createServer } from "node:http";
import { readFileSync, mkdtempSync, rmSync } from "node:fs";
import { join } from "node:path";
import { tmpdir } from "node:os";
import { spawn } from "node:child_process";

const args = process.argv.slice(2);
const dir = args[0];
if (!dir) {
  console.error("usage: node .ci/browser-shaders.mjs DIR [--browser PATH] [--timeout SECONDS]");
  process.exit(2);
}
const option = (name, fallback) => {
  const i = args.indexOf(name);
  return i >= 0 && i + 1 < args.length ? args[i + 1] : fallback;
};
const browser = option("--browser", "/usr/bin/chromium-headless-shell");
const timeoutSeconds = Number(option("--timeout", "600"));
// Pipelines not built (`--skip-pipeline NAME`, repeatable: a shader's name skips all of its
// entry points, an entry point's name that one), for pipelines the browser's software backend
// cannot build; their module is still compiled and validated.
const skipPipelines = args.flatMap((a, i) => (a === "--skip-pipeline" ? [args[i + 1]] : []));
// Shaders whose name contains TEXT (`--modules-only TEXT`, repeatable): compiled and validated,
// their pipelines not built. For variants whose WGSL differs from a variant built in full only
// by a constant (the software backend's two builds of each tracing pass), where the
// software-rendered pipeline build would only take the step's time.
const modulesOnly = args.flatMap((a, i) => (a === "--modules-only" ? [args[i + 1]] : []));

// index.txt: "file<TAB>variant name<TAB>native features" per line; the third column is empty for
// portable WGSL. A variant that needs a native feature WebGPU lacks (the hardware ray-query
// backend's tracing passes) is not compiled here: its portable fallback is listed beside it and
// must be in the dump (it is compiled like every portable variant).
const all = readFileSync(join(dir, "index.txt"), "utf8")
  .split("\n")
  .filter((l) => l.length > 0)
  .map((l) => {
    const [file, name, features = "", fallback = ""] = l.split("\t");
    return { file, name, features, fallback };
  });
const shaders = all.filter((s) => s.features === "");
for (const s of all.filter((s) => s.features !== "")) {
  if (!shaders.some((p) => p.name === s.fallback)) {
    console.error(`browser-shaders: ${s.name} needs ${s.features} and has no portable fallback`);
    process.exit(2);
  }
  console.log(`native-only (${s.features}): ${s.name}; fallback compiled: ${s.fallback}`);
}

// The page: compiles the shaders one by one and posts a result per shader, then "done".
const page = `<!doctype html><meta charset="utf-8"><script type="module">
const post = (path, body) => fetch(path, { method: "POST", body: JSON.stringify(body) });
try {
  if (!navigator.gpu) throw new Error("navigator.gpu is missing (WebGPU disabled?)");
  const adapter = await navigator.gpu.requestAdapter();
  if (!adapter) throw new Error("requestAdapter() gave no adapter");
  const info = adapter.info ?? {};
  const device = await adapter.requestDevice(); // WebGPU's default limits, no features
  await post("/adapter", { vendor: info.vendor, architecture: info.architecture,
                           description: info.description });
  const shaders = await (await fetch("/shaders.json")).json();
  const skip = await (await fetch("/skip.json")).json();
  const modulesOnly = await (await fetch("/modules-only.json")).json();
  for (const s of shaders) {
    const code = await (await fetch("/shader/" + encodeURIComponent(s.file))).text();
    const result = { name: s.name, file: s.file, messages: [], pipelines: [] };
    device.pushErrorScope("validation");
    const module = device.createShaderModule({ code, label: s.name });
    const info = await module.getCompilationInfo();
    for (const m of info.messages) {
      result.messages.push(m.type + " at " + m.lineNum + ":" + m.linePos + ": " + m.message);
    }
    const entries = [...code.matchAll(/@compute[^]*?fn\\s+([A-Za-z_][A-Za-z0-9_]*)\\s*\\(/g)]
      .map((m) => m[1]);
    for (const entryPoint of entries) {
      if (skip.includes(entryPoint) || skip.includes(s.name)
          || modulesOnly.some((m) => s.name.includes(m))) {
        result.pipelines.push({ entryPoint, ok: true, skipped: true });
        continue;
      }
      await post("/progress", { name: s.name, entryPoint });
      try {
        await device.createComputePipelineAsync({
          layout: "auto", compute: { module, entryPoint }, label: s.name + " " + entryPoint });
        result.pipelines.push({ entryPoint, ok: true });
      } catch (e) {
        result.pipelines.push({ entryPoint, ok: false, error: String(e.message ?? e) });
      }
    }
    const error = await device.popErrorScope();
    if (error) result.messages.push("validation: " + error.message);
    await post("/result", result);
  }
  await post("/done", {});
} catch (e) {
  await post("/fatal", { error: String(e.message ?? e) });
}
</script>`;

let reported = 0;
let lastProgress = "nothing yet";
let failed = 0;
const started = Date.now();
let finish;
const finished = new Promise((resolve) => (finish = resolve));

const server = createServer((req, res) => {
  let body = "";
  req.on("data", (c) => (body += c));
  req.on("end", () => {
    const url = decodeURIComponent(req.url);
    if (req.method === "GET" && url === "/") {
      res.writeHead(200, { "content-type": "text/html" }).end(page);
    } else if (req.method === "GET" && url === "/modules-only.json") {
      res.writeHead(200, { "content-type": "application/json" }).end(JSON.stringify(modulesOnly));
    } else if (req.method === "GET" && url === "/skip.json") {
      res.writeHead(200, { "content-type": "application/json" }).end(JSON.stringify(skipPipelines));
    } else if (req.method === "GET" && url === "/shaders.json") {
      res.writeHead(200, { "content-type": "application/json" }).end(JSON.stringify(shaders));
    } else if (req.method === "GET" && url.startsWith("/shader/")) {
      const file = url.slice("/shader/".length);
      if (!shaders.some((s) => s.file === file)) {
        res.writeHead(404).end();
        return;
      }
      res.writeHead(200, { "content-type": "text/plain" }).end(readFileSync(join(dir, file)));
    } else if (req.method === "POST") {
      res.writeHead(204).end();
      const data = JSON.parse(body || "{}");
      if (url === "/adapter") {
        console.log(`browser-shaders: WebGPU adapter: ${JSON.stringify(data)}`);
      } else if (url === "/result") {
        reported += 1;
        const errors = data.messages.filter((m) => !m.startsWith("warning") && !m.startsWith("info"));
        const bad = data.pipelines.filter((p) => !p.ok);
        const ok = errors.length === 0 && bad.length === 0 && data.pipelines.length > 0;
        if (!ok) failed += 1;
        const skipped = data.pipelines.filter((p) => p.skipped).map((p) => p.entryPoint);
        const what =
          `${data.pipelines.length} entry points` +
          (skipped.length > 0 ? `; pipeline not built: ${skipped.join(", ")}` : "");
        console.log(`${ok ? "ok  " : "FAIL"} ${data.name} (${what})`);
        for (const m of data.messages) console.log(`       ${m}`);
        for (const p of bad) console.log(`       ${p.entryPoint}: ${p.error}`);
        if (data.pipelines.length === 0) console.log("       no compute entry point found");
      } else if (url === "/done") {
        finish(failed === 0 && reported === shaders.length ? 0 : 1);
      } else if (url === "/progress") {
        lastProgress = `${data.name}: creating the pipeline of ${data.entryPoint}`;
      } else if (url === "/fatal") {
        console.error(
          `browser-shaders: ${data.error} (after ${reported} of ${shaders.length} shaders; last: ${lastProgress})`,
        );
        finish(2);
      }
    } else {
      res.writeHead(404).end();
    }
  });
});

server.listen(0, "127.0.0.1", () => {
  const { port } = server.address();
  const profile = mkdtempSync(join(tmpdir(), "ksrt-browser-"));
  const chrome = spawn(
    browser,
    [
      "--no-sandbox",
      "--headless",
      "--enable-unsafe-webgpu",
      "--use-webgpu-adapter=swiftshader",
      "--disable-gpu-sandbox",
      // On a loaded 2-core machine a large pipeline can take SwiftShader longer to compile than
      // the GPU process's hang watchdog allows (the watchdog then kills the GPU process).
      "--disable-gpu-watchdog",
      "--disable-background-networking",
      "--disable-component-update",
      "--no-first-run",
      `--user-data-dir=${profile}`,
      `http://127.0.0.1:${port}/`,
    ],
    { stdio: ["ignore", "ignore", "pipe"] },
  );
  let stderr = "";
  chrome.stderr.on("data", (c) => (stderr = (stderr + c).slice(-4000)));
  chrome.on("exit", (code) => {
    if (reported < shaders.length) {
      console.error(`browser-shaders: the browser exited (${code}) after ${reported} shaders:\n${stderr}`);
      finish(2);
    }
  });
  const timer = setTimeout(() => {
    console.error(`browser-shaders: no report within ${timeoutSeconds} s (${reported} of ${shaders.length}):\n${stderr}`);
    finish(2);
  }, timeoutSeconds * 1000);
  finished.then((status) => {
    clearTimeout(timer);
    const seconds = ((Date.now() - started) / 1000).toFixed(1);
    console.log(
      `browser-shaders: ${reported - failed} of ${shaders.length} shaders compile, ` +
        `${failed} fail, ${shaders.length - reported} not reached (${seconds} s)`,
    );
    if (status === 2) console.log(`browser-shaders: the browser's last messages:\n${stderr}`);
    chrome.kill("SIGKILL");
    server.close();
    rmSync(profile, { recursive: true, force: true });
    process.exit(status);
  });
});
