"""scripts/ensemble_convergence.py: its numerical configurations (docs/research/pb-speed.md)."""

import pytest

from .helpers import load_file_module


@pytest.fixture(scope="module")
def script():
    return load_file_module("scripts/ensemble_convergence.py")


def test_a_config_reads_spacing_rate_and_an_optional_content_spacing(script):
    plain = script.Config.parse("40:1200")
    assert (plain.spacing, plain.timestep, plain.content_spacing) == (0.04, 1 / 1200, None)
    assert plain.label == "40 mm, 1/1200 s"
    content = script.Config.parse("40:1200:100")
    assert content.content_spacing == pytest.approx(0.1)
    assert content.label == "40 mm, 1/1200 s, content 100 mm"
    # the spacing reaches both shells, the content spacing the soft content
    scene = script._Factory(content, "E3")(0).options.scene
    assert (scene.spacing, scene.soft_shell_spacing) == (0.04, 0.04)
    assert scene.soft_spacing == pytest.approx(0.1)
    assert script._Factory(plain, "E3")(0).options.scene.soft_spacing == pytest.approx(0.1)


@pytest.mark.parametrize("text", ["40", "40:1200:100:5", "40:x"])
def test_a_bad_config_is_refused_naming_the_option(script, text, capsys):
    with pytest.raises(SystemExit):
        script.main(["--configs", text])
    assert "--configs" in capsys.readouterr().err
