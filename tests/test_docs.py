"""The pages render whole: every relative link and image of README.md, CHANGELOG.md,
CONTRIBUTING.md and docs/*.md resolves to a file (and an anchor to a heading of it), each
picture the README shows is a committed PNG of the gallery that ``reproduce --gallery`` makes,
and no page tells the story of how the project was written."""

import re
import struct
from pathlib import Path

import pytest

from femgrid_mpm.reproduce.gallery import GALLERY

ROOT = Path(__file__).parents[1]
PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "CONTRIBUTING.md", *sorted((ROOT / "docs").glob("*.md"))]
#: [text](target) and ![alt](target), outside code: the target up to a space or ")"
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def prose(text: str) -> str:
    """The text without fenced code blocks and inline code (a link there is not a link)."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    headings = re.findall(r"^#{1,6} (.+)$", prose(path.read_text()), flags=re.M)
    return {slug(heading) for heading in headings}


def links(path: Path) -> list[str]:
    return [target for target in LINK.findall(prose(path.read_text())) if not re.match(r"[a-z]+:", target)]


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_every_relative_link_resolves(page):
    assert page.exists(), page
    broken = []
    for target in links(page):
        name, _, anchor = target.partition("#")
        file = (page.parent / name).resolve() if name else page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            broken.append(target)
    assert broken == [], f"{page.name}: broken links"


def png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n", f"{path.name} is not a PNG"
    return struct.unpack(">II", header[16:24])


def test_the_readme_shows_the_gallery_and_each_picture_exists():
    images = [target for target in LINK.findall(prose((ROOT / "README.md").read_text()))
              if target.endswith(".png")]
    assert images[0] == "docs/gallery/work_precision.png", "the work-precision diagram comes first"
    for image in images:
        path = ROOT / image
        assert path.parent == ROOT / "docs" / "gallery", image
        assert path.name in GALLERY, f"{image}: not a figure reproduce --gallery makes"
        width, height = png_size(path)
        assert 300 <= width <= 2000 and 200 <= height <= 2000, (image, width, height)
        assert path.stat().st_size < 500_000, image  # a few hundred KB: figures at dpi ~100
    assert sorted({Path(image).name for image in images}) == sorted(GALLERY), "every gallery picture is shown"


def test_the_first_screen_has_the_commands_a_picture_and_the_scene_reference():
    first_screen = "\n".join((ROOT / "README.md").read_text().splitlines()[:40])
    assert "    pip install -e . && femgrid-mpm reproduce --out results\n" in first_screen
    assert '    pip install -e ".[test]" && python -m pytest\n' in first_screen
    assert "](docs/scenes.md)" in first_screen
    assert "![" in first_screen


def test_the_readme_scene_is_valid(tmp_path, capsys):
    from helpers import run_cli

    (scene,) = re.findall(r"```toml\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    (tmp_path / "bar.toml").write_text(scene)
    code, _, err = run_cli(["info", tmp_path / "bar.toml"], capsys)
    # nothing on stderr but, where this tree's kernel cache is still cold, the note that says so
    assert code == 0 and all("compiling the numba kernels" in line for line in err.splitlines())


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(ROOT)) for p in PAGES])
def test_no_page_tells_how_it_was_written(page):
    text = page.read_text()
    assert not re.search(r"\bsessions?\b", text, flags=re.I), page.name
    if page.name != "CHANGELOG.md":  # dated entries belong there, one line each
        assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text), f"{page.name}: a dated paragraph"
