"""The dashboard in a real browser: Debian's chromium driven by Playwright, against the live
service replaying the sample recording through the real pipeline."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from test_service_support import REPO, TOKEN, sample_recording, serve, wait_for

pytestmark = pytest.mark.timeout(120)

CHROMIUM = Path("/usr/bin/chromium")
ARTIFACTS = REPO / "test-artifacts"
BROWSER_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
]
TRUCK_RGB = (255, 176, 32)  # --truck in style.css / COLORS.truck in app.js


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.is_file():
        pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium)")
    playwright = pytest.importorskip("playwright.sync_api")
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=BROWSER_ARGS)
        yield browser
        browser.close()


def _truck_pixels(page) -> int:
    """Pixels of the yard canvas drawn in the truck's colour."""
    return page.evaluate(
        """([r, g, b]) => {
        const c = document.getElementById('yard');
        const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
        let n = 0;
        for (let i = 0; i < d.length; i += 4)
            if (Math.abs(d[i] - r) < 8 && Math.abs(d[i + 1] - g) < 8 && Math.abs(d[i + 2] - b) < 8) n++;
        return n;
    }""",
        list(TRUCK_RGB),
    )


def test_dashboard_shows_vehicle_and_edits_parameters(browser, tmp_path):
    server, service = serve(sample_recording(), params_file=tmp_path / "params.yaml")
    errors: list[str] = []
    with server:
        page = browser.new_page(viewport={"width": 1400, "height": 950})
        page.on("pageerror", lambda err: errors.append(str(err)))
        page.goto(server.url + "/")

        # Live: a vehicle with its hitch angle as a number, drawn on the canvas.
        page.wait_for_selector("#vehicles .vehicle .hitch", timeout=30_000)
        hitch = wait_for(
            lambda: re.fullmatch(r"[+-]\d+\.\d°", page.inner_text("#vehicles .vehicle .hitch").strip()),
            timeout_s=30,
            what="a numeric hitch angle",
        )
        vid = int(page.get_attribute("#vehicles .vehicle", "data-id"))
        latest_ids = [v["id"] for v in (service.runner.latest or {}).get("vehicles", [])]
        assert hitch and (vid in latest_ids or vid <= max(latest_ids, default=vid))
        assert page.inner_text("#conn-status") == "live"
        assert _truck_pixels(page) > 20
        sensor_rows = page.locator("#sensors tbody tr")
        assert sensor_rows.count() == len(service.runner.source.sensor_names)

        # An invalid edit: refused with the field, value and allowed range; nothing changes.
        page.fill("#token", TOKEN)
        page.dispatch_event("#token", "change")
        page.click("details[data-path='clustering'] > summary")
        field = "#param-editor [data-path='clustering.tolerance_m']"
        page.fill(field, "9")
        page.click("#apply-params")
        page.wait_for_function("document.getElementById('param-status').textContent.includes('refused')")
        shown = page.inner_text("#param-errors")
        assert "clustering.tolerance_m = 9" in shown and "<= 5" in shown
        assert "invalid" in page.get_attribute(field, "class") and service.store.version == 0

        # A valid edit goes through: a new version, applied by the pipeline.
        page.fill(field, "0.5")
        page.click("#apply-params")
        page.wait_for_function("document.getElementById('param-status').textContent.includes('version 1')")
        assert service.store.version == 1 and service.store.params.clustering.tolerance_m == 0.5
        wait_for(lambda: service.runner.params_version == 1, what="the pipeline to apply version 1")
        assert service.runner.pipeline.params.clustering.tolerance_m == 0.5
        page.wait_for_function("document.getElementById('params-info').textContent === 'params v1'")
        assert page.input_value(field) == "0.5"

        page.wait_for_timeout(1500)  # some hitch history in the plot
        ARTIFACTS.mkdir(exist_ok=True)
        shot = ARTIFACTS / "dashboard.png"
        page.screenshot(path=str(shot))
        page.close()
    assert shot.stat().st_size > 10_000
    assert not errors, errors


def _state(frame, vehicles):
    return {
        "type": "state",
        "frame": frame,
        "stamp_s": frame / 10,
        "latency_ms": {"total": 1.0},
        "faults": {},
        "dropped": {},
        "clusters": [],
        "vehicles": vehicles,
    }


def _vehicle(vid, name, hitch, whole=True):
    unit = {
        "track_id": vid * 10,
        "center": [0.0, 0.0, 1.0],
        "yaw_deg": 0.0,
        "dimensions": [4.0, 2.0, 2.0],
        "points": 50,
    }
    return {
        "id": vid,
        "vehicle": name,
        "hitch_deg": hitch,
        "truck": unit,
        "trailer": unit if whole else None,
        "tractor_to_trailer": None,
    }


def test_dashboard_shows_confirmed_vehicles_only_unconfirmed_greyed_on_request(browser, tmp_path):
    server, _ = serve(sample_recording())
    with server:
        page = browser.new_page()
        # No live stream: the states below are the only ones the page sees.
        page.add_init_script("window.WebSocket = class { constructor() {} send() {} close() {} };")
        page.goto(server.url + "/")

        def shown():
            return page.eval_on_selector_all("#vehicles .vehicle", "rows => rows.map(r => [r.dataset.id, r.className])")

        for k in range(4):  # a vehicle seen whole in 4 states and a half-seen one (only a truck): neither is shown
            page.evaluate(
                "s => onState(s)", _state(k, [_vehicle(3, "man_tgx", 12.0), _vehicle(7, "twizy", 100.0, whole=False)])
            )
        page.wait_for_timeout(100)
        assert shown() == []
        page.evaluate(
            "s => onState(s)", _state(4, [_vehicle(3, "man_tgx", 12.5), _vehicle(7, "twizy", 100.0, whole=False)])
        )
        page.wait_for_timeout(100)
        assert shown() == [["3", "vehicle"]]
        assert page.evaluate("[...store.hitch.keys()]") == [3]  # the phantom never enters the hitch plot
        page.check("#show-unconfirmed")
        page.wait_for_timeout(100)
        assert shown() == [["3", "vehicle"], ["7", "vehicle unconfirmed"]]
        page.evaluate("s => onState(s)", _state(5, [_vehicle(7, "twizy", 100.0, whole=False)]))
        page.uncheck("#show-unconfirmed")
        page.wait_for_timeout(100)
        assert shown() == []  # vehicle 3 left: no longer shown
        page.close()
