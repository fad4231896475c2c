"""Draw a standing body in a scene with a chair seat and a step to a PNG (docs/body.png).

    MUJOCO_GL=egl uv run python benchmarks/render_body.py --out docs/body.png [--height 1.75]

Without an OpenGL context (MUJOCO_GL unset and no display) it draws a matplotlib projection.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from physpose.body import build_body, standing_qpos
from physpose.render_body import BACKENDS, RenderConfig, render_png
from physpose.scene import SceneConfig, parse_obstacle
from physpose.shape import BodyShape

CHAIR = "box:-0.55,0.45,0.225,0.45,0.45,0.45,20"  # a seat behind and to the person's left
STEP = "box:0.55,-0.35,0.09,0.35,0.9,0.18,-10"  # a step in front and to the right


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/body.png"))
    parser.add_argument("--height", type=float, default=1.75)
    parser.add_argument("--mass", type=float)
    parser.add_argument("--backend", choices=BACKENDS, default="auto")
    args = parser.parse_args()
    scene = SceneConfig(obstacles=(parse_obstacle(CHAIR), parse_obstacle(STEP)))
    body = build_body(BodyShape.from_height(args.height, args.mass), scene)
    backend = render_png(body, standing_qpos(body), args.out,
                         RenderConfig(width=640, height=720, backend=args.backend))
    print(f"wrote {args.out} ({backend}; {body.total_mass:.1f} kg, {body.model.nu} dof)")


if __name__ == "__main__":
    main()
