"""The CLI plot and the dashboard speak one language: contacts numbered from 0 (as in
``ctp simulate`` and the tutorial) and the same colour for each contact state."""

from __future__ import annotations

import json
import re

import matplotlib.colors as mcolors
import matplotlib.pyplot as plt
from service_helpers import EXAMPLES, ROOT

from analysis.loader import load_scene
from ctp.plot import STATE_COLOURS, draw_scene


def test_state_colours_match_the_dashboard() -> None:
    js = "\n".join(p.read_text() for p in sorted((ROOT / "api" / "static").glob("*.js")))
    found = re.findall(r"(?:export )?const COLORS = (\{[^}]*\});", js)
    assert len(found) == 1, "the dashboard defines its state colours once"
    m = re.search(r"(\{[^}]*\})", found[0])
    assert m is not None
    dashboard = json.loads(re.sub(r"(\w+):", r'"\1":', m.group(1)))
    assert dashboard == STATE_COLOURS


def test_plot_numbers_contacts_from_zero_in_state_colours() -> None:
    scene = load_scene(EXAMPLES / "planar_disk_envelope.json")
    fig, ax = plt.subplots()
    try:
        draw_scene(ax, scene, "FDFDD")
        labels = {t.get_text().strip(): t.get_color() for t in ax.texts if t.get_text().strip()}
    finally:
        plt.close(fig)
    assert set(labels) == {"0:F", "1:D", "2:F", "3:D", "4:D"}
    for text, colour in labels.items():
        assert mcolors.to_hex(colour) == STATE_COLOURS[text[-1]], text
