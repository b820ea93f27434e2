"""Prompt checks shared by the pipeline, the planner and the text encoders (no torch needed)."""

import subprocess
import sys

import pytest

from motok_robot.errors import InputError
from motok_robot.text.validate import MAX_TEXT_CHARS, check_text, check_texts


def test_import_is_torch_free():
    code = "import sys, motok_robot.text, motok_robot.pipeline; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_check_text_collapses_whitespace():
    assert check_text("  a person\n walks\tforward ") == "a person walks forward"


@pytest.mark.parametrize("text, message", [
    ("", r"^text is empty: give a sentence"),
    (" \n", r"^text is empty"),
    (3, r"^text must be a string, got int"),
    ("a" * (MAX_TEXT_CHARS + 1), rf"^text is {MAX_TEXT_CHARS + 1} characters long; at most {MAX_TEXT_CHARS}"),
])
def test_check_text_rejects(text, message):
    with pytest.raises(InputError, match=message):
        check_text(text)


def test_planner_and_pipeline_use_the_same_check():
    from motok_robot import pipeline
    from motok_robot.planner.generate import check_text as planner_check

    assert pipeline.check_text is check_text
    assert planner_check("a  b") == "a b"
    with pytest.raises(InputError, match=r"text is empty: .*\(or use --unconditional\)"):
        planner_check("")
    assert pipeline.MAX_TEXT_CHARS == MAX_TEXT_CHARS


def test_check_texts_names_the_prompt():
    assert check_texts(["a  b", "c"]) == ["a b", "c"]
    with pytest.raises(InputError, match=r"text #1 is empty"):
        check_texts(["ok", " "])
    with pytest.raises(InputError, match="single string"):
        check_texts("a person walks")
