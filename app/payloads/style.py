"""The app's colours and colour maps, shared by every view (library material names)."""

from __future__ import annotations

from app.payloads import encode

# Material colours of the 3D scene (library names); hidden facets are grey.
MATERIAL_COLORS = {
    "ideal_diffuse": "#80deea",
    "ideal_specular": "#ce93d8",
    "solar_panel": "#3d5afe",
    "coating_1": "#ffb300",
    "coating_2": "#eceff1",
    "lambertian": "#66bb6a",
}
OTHER_MATERIAL_COLOR = "#ff8a65"
HIDDEN_COLOR = "#4a4d55"
TARGET_POINT_COLOR = "#4fc3f7"
OUTLIER_COLOR = "#ff1744"
PINNED_POINT_COLOR = "#cfd8dc"  # a pinned frame's cloud, drawn faintly (app.logic.compare)
RANGE_CMAP = "viridis"
SNR_CMAP = "viridis"
ERROR_CMAP = "coolwarm"  # range error: blue short, white on the truth, red long (diverging)
PART_CMAP = "tab20"  # target parts: one of 20 distinct colours each (qualitative)
POWER_CMAP = "inferno"
NO_ECHO_RGB = (30, 30, 36)
SNR_FLOOR = 1e-2  # the SNR histogram starts here
# One colour per selected pixel: waveform traces and the markers on the array image.
SELECTION_COLORS = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#17becf",
)


def colorbar(title: str, cmap: str, lo_text: str, hi_text: str) -> dict:
    return {
        "title": title,
        "gradient": encode.css_gradient(cmap),
        "lo": lo_text,
        "hi": hi_text,
    }
