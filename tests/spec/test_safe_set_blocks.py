"""Reusable safe-set blocks keep the `when` window of the `use` that includes them (composite safe sets)."""
import numpy as np

from mpgspec.api import compile_project
from mpgspec.spec.loader import load_project

PROJECT = """\
project: blocks
system:
  name: cart
  states: [p, v]
  inputs: [a]
  dynamics: {f: [v, 0], g: [[0], [1]]}
safe_sets:
  low: [{name: below, h: "1 - p"}]
  high: [{name: above, h: "p - 2"}, {name: late_above, h: "p - 3", when: [0.5, 5]}]
primitives:
  - name: Hop
    class: transient
    domain: [0, 2]
    next: Hop2
    setpoint: {expr: [0, 0]}
    controller: {type: expression, u: ["0"]}
    safe_set:
      - {use: low, when: [0, 1]}
      - {use: high, when: [1, 2]}
    roa: {radius: 0.1}
  - name: Hop2
    class: fixed
    setpoint: {expr: [0, 0]}
    controller: {type: expression, u: ["0"]}
    roa: {radius: 0.1}
"""


def test_use_with_when_restricts_every_function_of_the_block(tmp_path):
    (tmp_path / "project.yaml").write_text(PROJECT)
    spec = load_project(tmp_path / "project.yaml")
    hop = spec.primitive("Hop")
    assert [(f.name, f.when) for f in hop.safe_set] == [("below", (0, 1)), ("above", (1, 2)),
                                                        ("late_above", (1, 2))]
    p = compile_project(spec)["Hop"]
    x = np.array([2.5, 0.0])
    h = lambda t: np.array(p.h(x, t, 0, x)).ravel()  # noqa: E731
    assert h(0.5)[0] < 0 and h(0.5)[1] > 1e8  # only 'below' is active before t = 1
    assert h(1.5)[0] > 1e8 and h(1.5)[1] > 0 and h(1.5)[2] < 0  # then only the 'high' block
