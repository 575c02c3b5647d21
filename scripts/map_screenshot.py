"""Take docs/img/map.png: the demo fleet (master, robot_0 and robot_1 on the demo graph) on the
live map, mid-order, with robot_0 selected so its base and horizon show.

Run: .venv/bin/python scripts/map_screenshot.py [--out docs/img/map.png]
Needs chromium (apt-get install chromium).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

from playwright.async_api import async_playwright

REPO = Path(__file__).resolve().parents[1]
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


#: Both robots driving, more than 4 m from each other.
APART = """(() => {
  const [a, b] = [...window.vdaMap.store.vehicles.values()];
  const driving = [...window.vdaMap.statuses.values()].filter((s) => s === "driving").length;
  return driving === 2 && Math.hypot(a.x - b.x, a.y - b.y) > 4;
})()"""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


async def shoot(url: str, out: Path) -> None:
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(executable_path="/usr/bin/chromium", args=FLAGS)
        page = await browser.new_page(viewport={"width": 1360, "height": 760})
        await page.goto(url)
        await page.wait_for_function("() => window.vdaMap && window.vdaMap.ready")
        robot = page.locator('[data-vehicle="vda-sim/robot_1"]')
        await robot.wait_for()
        for _ in range(600):  # until both robots drive, apart (no traffic control yet)
            apart = await page.evaluate(APART)
            if apart:
                break
            await asyncio.sleep(0.1)
        await page.locator('tr[data-row-vehicle="vda-sim/robot_0"]').click()
        await asyncio.sleep(0.3)
        await page.screenshot(path=str(out))
        await browser.close()


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    cli.add_argument("--out", type=Path, default=REPO / "docs" / "img" / "map.png")
    args = cli.parse_args()
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    command = [sys.executable, "-m", "vda_demo", "--forever", "--api-port", str(port)]
    demo = subprocess.Popen(  # noqa: S603 - our interpreter, our module
        command, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        asyncio.run(asyncio.sleep(6))
        asyncio.run(shoot(f"http://127.0.0.1:{port}/", args.out))
    finally:
        demo.send_signal(signal.SIGINT)
        demo.wait(30)
    print(f"wrote {args.out}")  # noqa: T201
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
