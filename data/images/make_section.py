"""Writes data/images/section.nrrd, the bundled 2D label image
(data/scenes/section.toml), with nothing but Python's standard library.

    python data/images/make_section.py

A synthetic tissue section of 80 x 50 pixels of 0.5 mm (an ASCII NRRD
with a 2D space): a half-ellipse of tissue (label 1) on a flat base,
holding a stiffer nodule (label 2) and crossed by a vessel (label 3, not
part of the body: a hole). Deterministic: running it again writes the
same bytes.
"""

import os

HERE = os.path.dirname(os.path.abspath(__file__))
NX, NY = 80, 50


def label(i, j):
    if j < 2:
        return 0
    x, y = (i - 39.5) / 37.0, (j - 2.0) / 44.0
    if x * x + y * y > 1.0:
        return 0
    if (i - 24) ** 2 + (j - 20) ** 2 <= 16:
        return 3
    if (i - 52) ** 2 + (j - 24) ** 2 <= 36:
        return 2
    return 1


def main():
    rows = [" ".join(str(label(i, j)) for i in range(NX)) for j in range(NY)]
    header = [
        "NRRD0004",
        "# a synthetic tissue section: 1 tissue, 2 nodule, 3 vessel (data/images/make_section.py)",
        "type: uint8",
        "dimension: 2",
        f"sizes: {NX} {NY}",
        "space dimension: 2",
        "space directions: (0.5,0) (0,0.5)",
        "space units: \"mm\" \"mm\"",
        "space origin: (0,0)",
        "encoding: ascii",
    ]
    with open(os.path.join(HERE, "section.nrrd"), "w", newline="\n") as f:
        f.write("\n".join(header) + "\n\n" + "\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
