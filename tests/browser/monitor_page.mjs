// End to end in a real headless browser: replays the default recording with --monitor, opens
// the page in Debian's chromium (driven by playwright-core) while the replay runs, and checks
// that the map-size chart and the texture gallery update. Keeps a screenshot.
//
//   node monitor_page.mjs TESSERA_BINARY RECORDING ARTIFACT_DIR
// Exit codes: 0 passed, 1 failed, 77 skipped (no chromium or playwright-core).
import { spawn } from "node:child_process";
import { existsSync, mkdirSync, rmSync } from "node:fs";
import { join } from "node:path";

const SKIP = 77;
const [tessera, recording, artifacts] = process.argv.slice(2);
const chromiumPath = process.env.CHROMIUM ?? "/usr/bin/chromium";

let chromium;
try {
  ({ chromium } = await import("playwright-core"));
} catch {
  console.log("SKIP: playwright-core is not installed (npm ci --prefix tests/browser)");
  process.exit(SKIP);
}
if (!existsSync(chromiumPath)) {
  console.log(`SKIP: no browser at ${chromiumPath} (apt-get install chromium)`);
  process.exit(SKIP);
}
if (!existsSync(recording)) {
  console.log(`SKIP: ${recording} is not rendered`);
  process.exit(SKIP);
}
mkdirSync(artifacts, { recursive: true });
const out = join(artifacts, "monitor_run");
rmSync(out, { recursive: true, force: true });

// The run picks a free port and logs its URL.
const run = spawn(tessera, ["run", recording, "--out", out, "--monitor", "127.0.0.1:0", "--quiet"]);
let runLog = "";
const url = await new Promise((resolve, reject) => {
  const timer = setTimeout(() => reject(new Error("no monitor URL within 30 s:\n" + runLog)), 30000);
  run.stderr.on("data", (chunk) => {
    runLog += chunk;
    const found = runLog.match(/monitor: (http:\/\/[0-9.]+:[0-9]+\/)/);
    if (found) { clearTimeout(timer); resolve(found[1]); }
  });
  run.on("exit", (code) => reject(new Error(`tessera ended (${code}) before serving:\n${runLog}`)));
});
const runEnded = new Promise((resolve) => run.on("exit", resolve));

const failures = [];
const browser = await chromium.launch({ executablePath: chromiumPath, args: ["--no-sandbox"] });
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  page.on("pageerror", (error) => failures.push(`page error: ${error.message}`));
  await page.goto(url);
  const figures = () => page.evaluate(() => ({
    points: Number(document.getElementById("chart").dataset.points),
    textures: Number(document.getElementById("gallery").dataset.textures),
    images: document.querySelectorAll("#gallery img").length,
    state: document.getElementById("state").textContent,
    line: document.getElementById("line-before").getAttribute("points"),
  }));
  // Watch until the run ends (or 120 s): the chart must grow and the gallery must fill.
  const first = await figures();
  let last = first, grew = null, screenshot = false, shotAt = 0;
  const deadline = Date.now() + 120000;
  let ended = false;
  runEnded.then(() => { ended = true; });
  while (!ended && Date.now() < deadline) {
    await page.waitForTimeout(250);
    last = await figures();
    if (!grew && last.points > first.points + 5 && last.textures > first.textures) grew = { ...last };
    // A picture every 2 s while it runs: the last one kept shows the run near its end.
    if (grew && last.images > 0 && Date.now() - shotAt > 2000) {
      const decoded = await page.evaluate(() => [...document.querySelectorAll("#gallery img")]
          .every((img) => img.complete && img.naturalWidth > 0));
      if (decoded) {
        await page.screenshot({ path: join(artifacts, "monitor_page.png"), fullPage: true });
        screenshot = true;
        shotAt = Date.now();
      }
    }
  }
  console.log(`page first: ${JSON.stringify({ ...first, line: undefined })}`);
  console.log(`page while running: ${JSON.stringify({ ...(grew ?? last), line: undefined })}`);
  if (!grew) failures.push("the chart and gallery did not both update during the replay");
  if (grew && grew.state !== "running") failures.push(`state shown: ${grew.state}, not running`);
  if (grew && !/^[0-9.]+,[0-9.]+( [0-9.]+,[0-9.]+)+$/.test(grew.line)) {
    failures.push(`the before-reuse line is not drawn: "${grew.line}"`);
  }
  if (!screenshot) failures.push("no screenshot: no thumbnail was shown");
  else console.log(`screenshot: ${join(artifacts, "monitor_page.png")}`);
} finally {
  await browser.close();
  if (!run.exitCode && run.exitCode !== 0) run.kill("SIGINT");
}
const code = await runEnded;
if (code !== 0) failures.push(`tessera run exited ${code}:\n${runLog}`);
for (const failure of failures) console.log(`FAIL: ${failure}`);
process.exit(failures.length ? 1 : 0);
