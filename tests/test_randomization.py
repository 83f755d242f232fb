"""Each task's randomisation: the ranges it draws from are named constants
(rmbench.tasks.randomization.Uniform), read by its code; its docstring's "Randomization"
paragraph quotes every one of them and no other range, so the two cannot drift apart."""

import ast
import inspect
import re
import sys
from collections import Counter

import numpy as np
import pytest

from rmbench.tasks import TASKS
from rmbench.tasks.randomization import Uniform

NUMBER = r"-?\d*\.?\d+"
QUOTED = re.compile(rf"U\[\s*({NUMBER})\s*,\s*({NUMBER})\s*\]")  # may break across lines


def randomization_paragraph(doc: str) -> str:
    start = doc.index("Randomization:")
    end = doc.find("\n\n", start)
    return doc[start:] if end < 0 else doc[start:end]


def task_module(name: str):
    return sys.modules[TASKS[name].__module__]


def named_ranges(module) -> dict[str, Uniform]:
    return {k: v for k, v in vars(module).items() if isinstance(v, Uniform)}


@pytest.mark.parametrize("name", sorted(TASKS))
def test_the_docstring_quotes_each_named_range_and_no_other(name):
    module = task_module(name)
    named = Counter((r.low, r.high) for r in named_ranges(module).values())
    assert named, f"{name} names no randomisation range"
    paragraph = randomization_paragraph(module.__doc__)
    quoted = Counter((float(a), float(b)) for a, b in QUOTED.findall(paragraph))
    assert quoted == named, (f"{name}: quoted in the docstring only {dict(quoted - named)}, "
                             f"named in the code only {dict(named - quoted)}")


@pytest.mark.parametrize("name", sorted(TASKS))
def test_every_range_is_named_and_read(name):
    """No draw from a range typed where it is drawn (``rng.uniform(a, b)``), and no named range
    that the code does not read (the docstring would quote a dead number)."""
    module = task_module(name)
    tree = ast.parse(inspect.getsource(module))
    literal = [ast.unparse(node) for node in ast.walk(tree)
               if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
               and node.func.attr == "uniform" and (node.args or node.keywords)]
    assert not literal, f"{name} draws from unnamed ranges: {literal}"
    reads = Counter(node.id for node in ast.walk(tree)
                    if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load))
    unread = [k for k in named_ranges(module) if reads[k] == 0]
    assert not unread, f"{name} names ranges its code never draws from: {unread}"


def test_a_paragraph_that_drifted_from_its_constants_is_caught():
    doc = "Title.\n\nRandomization: x ~ U[-0.06,\n-0.02], y ~ U[0.10, 0.13].\n\nSuccess: U[9, 9]."
    quoted = Counter((float(a), float(b))
                     for a, b in QUOTED.findall(randomization_paragraph(doc)))
    assert quoted == Counter({(-0.06, -0.02): 1, (0.1, 0.13): 1})  # not the Success paragraph
    assert quoted != Counter({(-0.06, -0.02): 1, (0.1, 0.14): 1})


def test_a_named_draw_is_the_call_it_names_bit_for_bit():
    """Naming a range must not change an episode: same numbers from the same generator state,
    one at a time or several at once."""
    yaw, offset = Uniform(-0.4, 0.4), Uniform(-0.008, 0.008)
    named, literal = np.random.default_rng(3), np.random.default_rng(3)
    for _ in range(5):
        a = yaw.draw(named)
        assert isinstance(a, float) and a == literal.uniform(-0.4, 0.4)
        np.testing.assert_array_equal(offset.draw(named, 2), literal.uniform(-0.008, 0.008, 2))
    assert named.random() == literal.random()


def test_a_range_is_closed_and_ordered():
    r = Uniform(-0.75, 0.75)
    assert -0.75 in r and 0.75 in r and 0.0 in r and 0.76 not in r
    assert str(r) == "U[-0.75, 0.75]"
    with pytest.raises(ValueError, match="low < high"):
        Uniform(0.2, 0.1)
