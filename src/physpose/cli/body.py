"""`physpose body`: write the MJCF of a body sized to a person, standing in a scene."""

from __future__ import annotations

import argparse
from pathlib import Path

from physpose.body import BodyConfig, build_body, standing_qpos
from physpose.errors import PhysposeError
from physpose.paths import check_output_file
from physpose.scene import SceneConfig, parse_obstacle, trampoline
from physpose.shape import BUILD_BMI, HEIGHT_RANGE, MASS_RANGE, SEXES, BodyShape


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "body", help="write the simulation model (MJCF) of a body of a given height and mass",
        description="Build the capsule body (16 three-axis joints, position servos) for a "
                    "person's height and mass in a scene (ground plane at z = 0, optional "
                    "boxes) and write it as MuJoCo XML. The model holds a keyframe "
                    "'standing' with the feet on the ground.")
    p.add_argument("--height", type=float, required=True, help="standing height, m (0.5-2.5)")
    p.add_argument("--mass", type=float, help="body mass, kg (20-300; default: from the "
                                              "height at the build's BMI)")
    p.add_argument("--build", choices=tuple(BUILD_BMI), default="average",
                   help="build used to estimate the mass (BMI: " + ", ".join(
                       f"{name} {bmi:g}" for name, bmi in BUILD_BMI.items()) + ")")
    p.add_argument("--sex", choices=SEXES, default="neutral",
                   help="column of the segment-mass table (de Leva 1996)")
    p.add_argument("--ground-friction", type=float, help="ground friction coefficient "
                                                         "(default 0.9)")
    p.add_argument("--ground-stiffness", type=float,
                   help="ground stiffness, MuJoCo direct solref units (1/s^2 per unit mass); "
                        "default 10000, the hardest floor stable at the body's 5 ms step")
    p.add_argument("--ground-damping", type=float,
                   help="ground damping, MuJoCo direct solref units (1/s); default: "
                        "critical for the stiffness")
    p.add_argument("--trampoline", action="store_true",
                   help="a soft, springy floor that bounces (stiffness 150, damping 1.5; not "
                        "with --ground-stiffness/--ground-damping)")
    p.add_argument("--obstacle", action="append", default=[], metavar="box:x,y,z,sx,sy,sz[,yaw]",
                   help="a box in world coordinates: centre and full sizes in metres, "
                        "optional yaw in degrees (repeatable)")
    p.add_argument("--out", type=Path, required=True, help="MJCF file to write")
    p.add_argument("--png", type=Path, help="also draw the standing body and scene to this PNG "
                                            "(MuJoCo with MUJOCO_GL=egl, else matplotlib)")
    p.set_defaults(func=_run)


def scene_from_args(args: argparse.Namespace) -> SceneConfig:
    """The SceneConfig the ground and obstacle options describe (`physpose body` and
    `physpose reconstruct`)."""
    obstacles = []
    for i, text in enumerate(args.obstacle):
        try:
            obstacles.append(parse_obstacle(text))
        except PhysposeError as err:
            raise PhysposeError(f"--obstacle #{i + 1}: {err.problem}", remedy=err.remedy) from None
    scene = SceneConfig(obstacles=tuple(obstacles))
    direct = args.ground_stiffness is not None or args.ground_damping is not None
    if args.trampoline and direct:
        raise PhysposeError("--trampoline sets the floor's stiffness and damping itself",
                            remedy="give either --trampoline or --ground-stiffness/"
                                   "--ground-damping")
    if args.trampoline:
        scene = trampoline(scene)
    return scene.with_ground(args.ground_stiffness, args.ground_damping, args.ground_friction)


def check_person(height: float | None, mass: float | None) -> None:
    """Range checks of --height/--mass before any heavy work (reconstruct, fit)."""
    if mass is not None and height is None:
        BodyShape.from_height(1.75, mass)
    elif height is not None:
        BodyShape.from_height(height, mass)


def _check_range(option: str, value: float | None, bounds: tuple[float, float], unit: str,
                 example: str) -> None:
    if value is not None and not bounds[0] <= value <= bounds[1]:
        raise PhysposeError(f"{option} {value:g} {unit} is outside {bounds[0]:g}-{bounds[1]:g} "
                            f"{unit}", remedy=f"give it in {unit}, e.g. {option} {example}")


def _run(args: argparse.Namespace) -> int:
    _check_range("--height", args.height, HEIGHT_RANGE, "m", "1.75")
    _check_range("--mass", args.mass, MASS_RANGE, "kg", "70")
    if args.ground_friction is not None and not args.ground_friction >= 0:
        raise PhysposeError(f"--ground-friction {args.ground_friction:g} is not a coefficient "
                            ">= 0",
                            remedy="give a friction coefficient >= 0, e.g. 0.9")
    check_output_file(args.out)
    if args.png is not None:
        check_output_file(args.png, ".png", "--png")
    shape = BodyShape.from_height(args.height, args.mass, build=args.build, sex=args.sex)
    body = build_body(shape, scene_from_args(args), BodyConfig())
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(body.xml)
    print(f"wrote {args.out}: {body.model.nu} actuated dof, total mass {body.total_mass:.1f} kg, "
          f"height {shape.height:.2f} m")
    if args.png is not None:
        from physpose.render_body import render_png

        backend = render_png(body, standing_qpos(body), args.png)
        print(f"wrote {args.png} ({backend})")
    return 0
