"""Pieces shared by the scripts that write pages (eval_sets.py, report.py, results.py).

The markers that delimit a section one script keeps in a page another script writes,
and the display transform figures are drawn with. Kept here so that eval_sets.py and
report.py need not import each other.
"""

SECTION_BEGIN = "<!-- eval_sets.py: begin -->"
SECTION_END = "<!-- eval_sets.py: end -->"


def figure_tonemap(rgb):
    """dndenoise's default display transform (libtonemap/ocio/srgb.ocio, what -o out.png and
    --preview write): clamp to [0, 1], the sRGB curve, 8 bits; so figures look as users see them."""
    import numpy as np

    v = np.clip(np.nan_to_num(rgb, nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    encoded = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1 / 2.4) - 0.055)
    return (encoded * 255 + 0.5).astype(np.uint8)
