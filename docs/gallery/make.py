"""Make the gallery's pictures (``docs/gallery/*.png``) by running every example as a user runs it.

    python docs/gallery/make.py          # about two minutes on 2 CPU cores; reads ../shared/data

Each example writes its own picture into a scratch folder; the picture is scaled to at most
``WIDTH`` pixels across (Lanczos) and saved here, so the docs show what the examples make today.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
WIDTH = 1024

#: example -> the pictures it writes (joined side by side when several) and the gallery's file.
PICTURES = {
    "triplanar_bunny.py": (["triplanar_bunny.png"], "triplanar_bunny.png"),
    "stochastic_plane.py": (["stochastic_plane.png"], "stochastic_plane.png"),
    "bake_bunny.py": (["bake_bunny.png"], "bake_bunny.png"),
    "fit_splat.py": (["target.png", "fitted.png"], "fit_splat.png"),
    "torch_fit.py": (["target.png", "fitted.png"], "torch_fit.png"),
}


def main() -> None:
    with tempfile.TemporaryDirectory() as scratch:
        for script, (made, name) in PICTURES.items():
            out = Path(scratch) / script
            subprocess.run([sys.executable, str(REPO / "examples" / script), "--out", str(out)], cwd=REPO, check=True, stdout=subprocess.DEVNULL)
            images = [Image.open(out / m).convert("RGB") for m in made]
            whole = Image.new("RGB", (sum(i.width for i in images), max(i.height for i in images)))
            x = 0
            for image in images:
                whole.paste(image, (x, 0))
                x += image.width
            if whole.width > WIDTH:
                whole = whole.resize((WIDTH, round(whole.height * WIDTH / whole.width)), Image.LANCZOS)
            whole.save(HERE / name, optimize=True)
            print(f"wrote {HERE / name}")


if __name__ == "__main__":
    main()
