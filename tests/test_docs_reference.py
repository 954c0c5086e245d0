"""The documentation's reference pages are generated from the code and current
(scripts/docs_reference.py): the command line from the Typer app, the file formats from the
pydantic models, with a description on every key."""

import json

from parcelfit.schema import json_schema

from .helpers import load_file_module

gen = load_file_module("scripts/docs_reference.py")


def test_the_reference_pages_are_what_the_code_gives():
    stale = [
        rel
        for rel, text in gen.pages().items()
        if not (gen.OUT / rel).is_file() or (gen.OUT / rel).read_text(encoding="utf-8") != text
    ]
    first = ""
    if stale:  # the first lines that differ, so that a failure elsewhere says what changed
        import difflib

        rel = stale[0]
        old = (gen.OUT / rel).read_text(encoding="utf-8") if (gen.OUT / rel).is_file() else ""
        diff = difflib.unified_diff(old.splitlines(), gen.pages()[rel].splitlines(), lineterm="")
        first = "\n".join(list(diff)[:30])
    assert not stale, f"run python scripts/docs_reference.py: {stale} are out of date\n{first}"


def test_every_key_of_every_file_has_a_description():
    for slug, _, model, _ in gen._files():
        assert gen.undocumented(model) == [], slug


def test_units_are_in_the_schema():
    from parcelfit.sim.mujoco.rig import RigFile

    schema = json_schema(RigFile)
    wall = schema["$defs"]["WallEntry"]["properties"]
    assert wall["height"]["x-unit"] == "m" and "from" in wall and "to" in wall
    assert json.loads(json.dumps(schema))["required"][0] == "name"
