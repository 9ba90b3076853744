"""The validation report opened in a real headless Chromium (Debian's package)."""

import os
import re
import shutil
import subprocess

import pytest

from ntncontact.report.validation import Case, validate


def chromium() -> str:
    """Chromium's path; installed from Debian's packages when missing and we may (root)."""
    found = shutil.which("chromium")
    if found is None and os.geteuid() == 0 and shutil.which("apt-get"):
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        subprocess.run(["apt-get", "update", "-qq"], check=False, env=env,
                       capture_output=True, timeout=600)
        subprocess.run(["apt-get", "install", "-y", "-qq", "chromium"], check=False, env=env,
                       capture_output=True, timeout=900)
        found = shutil.which("chromium")
    if found is None:
        pytest.skip("chromium is not installed and cannot be installed here (needs root apt)")
    return found


def test_report_loads_with_every_section_and_image(tmp_path):
    cases = (Case("rod_impact", "rod_impact.toml", ("analysis.t_end=0.5",)),
             Case("rod_impact_lumped", "rod_impact.toml",
                  ("analysis.t_end=0.5", 'analysis.mass="lumped"')))
    validate(tmp_path, quick=True, cases=cases)
    report = tmp_path / "report.html"
    dom = subprocess.run(
        [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
         "--no-first-run", "--disable-background-networking", "--disable-component-update",
         "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}",
         "--virtual-time-budget=5000", "--allow-file-access-from-files", "--dump-dom",
         report.as_uri()],
        capture_output=True, text=True, timeout=120, check=True).stdout
    for case in cases:
        assert f"id=\"{case.name}\"" in dom
    images = re.findall(r"<img[^>]*>", dom)
    assert len(images) >= 2 * 4  # energies, momenta, deformed meshes, contact plots per case
    assert all('data-loaded="yes"' in img for img in images), images
    assert f'data-images-loaded="{len(images)}"' in dom
