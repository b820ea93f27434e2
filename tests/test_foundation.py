"""Package-level contract: canonical body, CLI, and torch-free robot-side imports."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from motok_robot.motion import skeleton as sk


def test_joint_order_is_smpl_humanml3d():
    assert sk.NUM_JOINTS == 22
    assert sk.JOINT_NAMES[:4] == ("pelvis", "left_hip", "right_hip", "spine1")
    assert sk.JOINT_NAMES[-2:] == ("left_wrist", "right_wrist")
    # every parent precedes its child, the root has none
    assert sk.PARENTS[0] == -1
    assert all(0 <= p < j for j, p in enumerate(sk.PARENTS) if j > 0)


def test_bone_lengths_symmetric_and_plausible():
    table = sk.bone_length_table()
    assert len(table) == 21
    for name, length in table.items():
        if name.startswith("left_"):
            assert length == pytest.approx(table["right_" + name[5:]], abs=1e-9)
        assert 0.03 < length < 0.5, name
    rest = sk.rest_pose()
    height = rest[:, 2].max() - rest[:, 2].min()
    assert 1.4 < height < 1.7  # head joint height of a ~1.7 m adult
    assert rest[sk.JOINT_INDEX["head"], 2] > rest[sk.JOINT_INDEX["pelvis"], 2] > rest[sk.JOINT_INDEX["left_knee"], 2]


def test_mirror_is_an_involution_and_swaps_sides():
    rng = np.random.default_rng(0)
    joints = rng.normal(size=(5, 22, 3))
    mirrored = sk.mirror_joints(joints)
    np.testing.assert_allclose(sk.mirror_joints(mirrored), joints)
    li, ri = sk.JOINT_INDEX["left_wrist"], sk.JOINT_INDEX["right_wrist"]
    np.testing.assert_allclose(mirrored[:, ri], joints[:, li] * [1, -1, 1])
    # the rest pose is its own mirror image
    np.testing.assert_allclose(sk.mirror_joints(sk.rest_pose()), sk.rest_pose(), atol=1e-12)


def test_axis_conversions_are_inverse_proper_rotations():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(7, 3))
    np.testing.assert_allclose(sk.zup_from_yup(sk.yup_from_zup(x)), x)
    # the permutation is a rotation (det +1), not a reflection
    perm = sk.yup_from_zup(np.eye(3))
    assert np.linalg.det(perm) == pytest.approx(1.0)
    # up is up: z (project) -> y (HumanML3D)
    np.testing.assert_allclose(sk.yup_from_zup(np.array([0.0, 0.0, 1.0])), [0.0, 1.0, 0.0])


def test_cli_help_lists_groups_and_each_subcommand_has_help():
    from motok_robot.cli import build_parser

    parser = build_parser()
    help_text = parser.format_help()
    for group in ("data", "train", "eval", "robots", "servo"):
        assert group in help_text
    # every registered subcommand (and sub-subcommand) answers --help with exit 0
    subparsers = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"][0]
    for name, sub in subparsers.choices.items():
        with pytest.raises(SystemExit) as exc:
            parser.parse_args([name, "--help"])
        assert exc.value.code == 0, name
        for action in sub._actions:
            if action.__class__.__name__ == "_SubParsersAction":
                for child in action.choices:
                    with pytest.raises(SystemExit) as exc:
                        parser.parse_args([name, child, "--help"])
                    assert exc.value.code == 0, (name, child)


def test_cli_reports_user_errors_in_one_line(capsys):
    from motok_robot.cli import main
    from motok_robot.errors import InputError

    import argparse

    def failing(_args: argparse.Namespace) -> int:
        raise InputError("clip.bvh: frame 3, joint 'Hips': NaN value")

    import motok_robot.cli as cli

    parser = cli.build_parser()
    original = cli.build_parser
    try:
        parser.set_defaults(func=failing)
        cli.build_parser = lambda: parser
        assert main([]) == 2
    finally:
        cli.build_parser = original
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["motok-robot: error: clip.bvh: frame 3, joint 'Hips': NaN value"]


def _run_python(code: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter (nothing imported yet) and require exit status 0."""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return result


def test_robot_side_modules_import_without_torch():
    _run_python(
        "import sys, importlib\n"
        "mods = ['motok_robot', 'motok_robot.cli', 'motok_robot.motion', 'motok_robot.robots',"
        " 'motok_robot.sim', 'motok_robot.servo', 'motok_robot.data', 'retarget']\n"
        "for m in mods:\n"
        "    importlib.import_module(m)\n"
        "from motok_robot.cli import build_parser\n"
        "build_parser()\n"
        "assert 'torch' not in sys.modules, 'torch was imported'\n"
    )


def test_cli_runs_non_servo_commands_without_dynamixel_sdk():
    """A training or evaluation box may lack dynamixel_sdk: only the servo commands need it."""
    result = _run_python(
        "import sys\n"
        "sys.modules['dynamixel_sdk'] = None  # as if not installed: importing it raises ImportError\n"
        "from motok_robot.cli import main\n"
        "assert main(['robots', 'list']) == 0\n"
        "try:\n"
        "    from motok_robot.servo import DynamixelBus\n"
        "except ImportError:\n"
        "    print('servo needs dynamixel_sdk')\n"
    )
    assert "servo needs dynamixel_sdk" in result.stdout
