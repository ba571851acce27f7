"""The README's "Use it in your controller" example runs as written (the docs cannot rot)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


CONTROLLER_PAGE = README.parent / "docs" / "controller.md"


def readme_example(page: Path = README) -> str:
    text = page.read_text(encoding="utf-8")
    match = re.search(r"<!-- controller-example -->\n```python\n(.*?)```\n<!-- /controller-example -->", text,
                      re.DOTALL)  # fmt: skip
    assert match, f"{page.name} lost its controller-example block"
    return match.group(1)


def test_readme_controller_example_runs(capsys):
    code = readme_example()
    assert 20 <= len(code.splitlines()) <= 45
    namespace = {}
    exec(compile(code, str(README), "exec"), namespace)
    assert "payload mode" in capsys.readouterr().out
    plant, coordination, simulator = namespace["plant"], namespace["coordination"], namespace["simulator"]
    assert simulator.get_context().get_time() == 0.5
    # The coordination's hand pose is the user's plant's, at the simulated (swinging) state.
    plant_context = plant.GetMyContextFromRoot(simulator.get_context())
    context = coordination.GetMyContextFromRoot(simulator.get_context())
    X_WH = coordination.GetOutputPort("X_WH_used").Eval(context)
    assert X_WH.IsNearlyEqualTo(namespace["hand"].CalcPoseInWorld(plant_context), 1e-12)
    # It followed the arm: the acrobot swung away from where it started.
    assert abs(plant.GetPositions(plant_context) - [0.5, -0.3]).max() > 0.05


def test_the_controller_page_shows_the_same_example():
    assert readme_example(CONTROLLER_PAGE) == readme_example()
