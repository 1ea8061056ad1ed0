"""Occupancy grids as Nav2's map_server reads them: PNG and other Pillow formats,
alpha channels, the three modes, unknown keys ignored with a warning.

Expected classes are worked out by hand from Nav2's map_io.cpp rules
(shade = mean of R, G, B (+ opacity in trinary mode), occ = 1 - shade or shade
with negate; occupied if occ > occupied_thresh, free if occ < free_thresh).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from companion.cli import main
from mavcore.errors import MapError
from mavcore.maps import load_ogm

ROOT = Path(__file__).resolve().parents[1]


def nav2_yaml(tmp_path: Path, image: str, *, mode=None, negate=0, occ=0.65, free=0.25, extra="") -> Path:
    """A map YAML written the way Nav2's map_saver writes it (keys, order, free 0.25)."""
    lines = [f"image: {image}"]
    if mode:
        lines.append(f"mode: {mode}")
    lines += ["resolution: 0.5", "origin: [-1.0, 2.0, 0.0]", f"negate: {negate}",
              f"occupied_thresh: {occ}", f"free_thresh: {free}"]
    y = tmp_path / (Path(image).stem + ".yaml")
    y.write_text("\n".join(lines) + "\n" + extra)
    return y


def classes(g) -> list[list[str]]:
    """Per cell 'o', 'f' or 'u', image order (north row first)."""
    out = np.where(g.occupied, "o", np.where(g.free, "f", "u"))[::-1]
    return out.tolist()


def test_grey_png_equals_the_same_pgm(tmp_path):
    rng = np.random.default_rng(5)
    px = rng.integers(0, 256, size=(6, 9)).astype(np.uint8)
    Image.fromarray(px, mode="L").save(tmp_path / "g.png")
    (tmp_path / "p.pgm").write_bytes(b"P5\n9 6\n255\n" + px.tobytes())
    a = load_ogm(nav2_yaml(tmp_path, "g.png"))
    b = load_ogm(nav2_yaml(tmp_path, "p.pgm"))
    assert np.array_equal(a.occupied, b.occupied) and np.array_equal(a.free, b.free)
    occ = 1.0 - px[::-1] / 255.0
    assert np.array_equal(a.occupied, occ > 0.65) and np.array_equal(a.free, occ < 0.25)
    assert a.resolution_m == 0.5 and a.origin_xy_m == (-1.0, 2.0)


def test_rgb_png_uses_the_mean_of_the_channels(tmp_path):
    # (255, 0, 0): shade 1/3, occ 2/3 > 0.65 -> occupied; (255, 255, 0): occ 1/3 -> unknown;
    # (255, 255, 200): occ = 1 - 710/765 = 0.072 -> free; (0, 0, 255) occ 2/3 -> occupied
    px = np.array([[[255, 0, 0], [255, 255, 0], [255, 255, 200], [0, 0, 255]]], dtype=np.uint8)
    Image.fromarray(px, mode="RGB").save(tmp_path / "c.png")
    assert classes(load_ogm(nav2_yaml(tmp_path, "c.png"))) == [["o", "u", "f", "o"]]
    Image.fromarray(px, mode="RGB").save(tmp_path / "c.bmp")
    assert classes(load_ogm(nav2_yaml(tmp_path, "c.bmp"))) == [["o", "u", "f", "o"]]


def test_alpha_is_averaged_in_trinary_and_unknown_in_scale(tmp_path):
    # white opaque: shade 1 -> free. white with alpha 0: trinary shade (3 x 255 + 0) / 1020 =
    # 0.75, occ 0.25 -> not < 0.25 -> unknown; scale: not opaque -> unknown.
    # black alpha 0: trinary shade 0 -> occupied; scale -> unknown.
    # grey 100 opaque: occ = 1 - (300 + 255) / 1020 = 0.456 (trinary) -> unknown;
    #                  scale: occ = 1 - 100/255 = 0.608 -> between -> unknown (graded cost)
    px = np.array([[[255, 255, 255, 255], [255, 255, 255, 0], [0, 0, 0, 0], [100, 100, 100, 255],
                    [30, 30, 30, 255]]], dtype=np.uint8)
    Image.fromarray(px, mode="RGBA").save(tmp_path / "a.png")
    assert classes(load_ogm(nav2_yaml(tmp_path, "a.png"))) == [["f", "u", "o", "u", "o"]]
    assert classes(load_ogm(nav2_yaml(tmp_path, "a.png", mode="scale"))) == [["f", "u", "u", "u", "o"]]


def test_raw_mode_ignores_negate_and_reads_percent(tmp_path):
    px = np.array([[0, 20, 100, 101, 255]], dtype=np.uint8)
    Image.fromarray(px, mode="L").save(tmp_path / "r.png")
    for negate in (0, 1):
        g = load_ogm(nav2_yaml(tmp_path, "r.png", mode="raw", negate=negate))
        # value/100: 0 free, 0.2 free (< 0.25), 1.0 occupied, 101 and 255 unknown
        assert classes(g) == [["f", "f", "o", "u", "u"]]


def test_negate_true_as_a_boolean(tmp_path):
    px = np.array([[0, 255]], dtype=np.uint8)
    Image.fromarray(px, mode="L").save(tmp_path / "n.png")
    assert classes(load_ogm(nav2_yaml(tmp_path, "n.png", negate="true"))) == [["f", "o"]]


def test_palette_and_16_bit_png(tmp_path):
    pal = Image.new("P", (3, 1))
    pal.putpalette([0, 0, 0, 254, 254, 254, 128, 128, 128] + [0] * 759)
    pal.putdata([0, 1, 2])
    pal.save(tmp_path / "p.png")
    assert classes(load_ogm(nav2_yaml(tmp_path, "p.png"))) == [["o", "f", "u"]]
    px16 = np.array([[0, 65535, 30000]], dtype=np.uint16)
    Image.fromarray(px16).save(tmp_path / "w.png")
    # 30000 / 65535 = 0.458 -> occ 0.542: unknown
    assert classes(load_ogm(nav2_yaml(tmp_path, "w.png"))) == [["o", "f", "u"]]


def test_unknown_keys_are_ignored_with_a_warning(tmp_path):
    Image.fromarray(np.full((2, 2), 254, np.uint8)).save(tmp_path / "k.png")
    g = load_ogm(nav2_yaml(tmp_path, "k.png", extra="map_type: occupancy\nfoo: 1\n"))
    assert g.free.all()
    assert len(g.warnings) == 2
    assert "map_type" in g.warnings[0] and "ignored" in g.warnings[0] and "k.yaml" in g.warnings[0]


@pytest.mark.parametrize("content, needle", [
    (b"\x89PNG\r\n\x1a\n" + b"\x00" * 20, "corrupt"),           # a PNG signature, garbage after it
    (b"GIF8", "not an image"),                                  # too short to be anything
])
def test_corrupt_images_are_one_line_map_errors(tmp_path, content, needle):
    (tmp_path / "bad.png").write_bytes(content)
    with pytest.raises(MapError) as exc:
        load_ogm(nav2_yaml(tmp_path, "bad.png"))
    assert "bad.png" in str(exc.value) and "\n" not in str(exc.value)
    assert needle in str(exc.value) or "not an image" in str(exc.value)


def test_truncated_png_via_the_cli_exit_2_nothing_written(tmp_path, capsys):
    import shutil

    mdir = tmp_path / "m"
    shutil.copytree(ROOT / "missions" / "flat-rectangle", mdir)
    px = np.full((10, 20), 254, np.uint8)
    Image.fromarray(px).save(mdir / "map.png")
    data = (mdir / "map.png").read_bytes()
    (mdir / "map.png").write_bytes(data[: len(data) // 2])
    y = mdir / "map.yaml"
    y.write_text(y.read_text().replace("image: map.pgm", "image: map.png"))
    out = tmp_path / "o"
    out.mkdir()
    rc = main(["plan", str(mdir / "mission.yaml"), "-o", str(out / "plan.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "map.png" in err[0]
    assert list(out.iterdir()) == []


def test_png_mission_plans_like_the_pgm_one(tmp_path, capsys):
    """The bundled flat-rectangle with its PGM converted to PNG and Nav2's extra key:
    the same grid (so the same plan), and the ignored key is reported on stderr and in
    plan.json's warnings."""
    import json
    import shutil

    mdir = tmp_path / "m"
    shutil.copytree(ROOT / "missions" / "flat-rectangle", mdir)
    Image.open(mdir / "map.pgm").save(mdir / "map.png")
    y = mdir / "map.yaml"
    y.write_text(y.read_text().replace("image: map.pgm", "image: map.png") + "map_type: occupancy\n")
    png, pgm = load_ogm(y), load_ogm(ROOT / "missions" / "flat-rectangle" / "map.yaml")
    assert np.array_equal(png.occupied, pgm.occupied) and np.array_equal(png.free, pgm.free)
    rc = main(["plan", str(mdir / "mission.yaml"), "-o", str(tmp_path / "png.json")])
    err = capsys.readouterr().err
    assert rc == 0 and "map_type" in err and "ignored" in err
    assert "map_type" in json.loads((tmp_path / "png.json").read_text())["warnings"][0]
