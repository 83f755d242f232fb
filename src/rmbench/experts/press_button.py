"""Expert for press_button: left button d1 times, middle d2 times, then confirm."""

from __future__ import annotations

from rmbench.experts.base import ScriptedExpert, register_expert


@register_expert
class PressButtonExpert(ScriptedExpert):
    task = "press_button"

    def plan(self, task):
        m, model = self.motion, task.model

        def counter(button):
            return lambda: button.count

        first = True
        for subtask, button, count in ((0, task.left, task.d1), (1, task.middle, task.d2)):
            for _ in range(count):
                yield from self.label(subtask, m.press("left", button.top(model), approach=first,
                                                         count=counter(button)))
                first = False
        yield from self.label(2, m.go_home("left"))
        yield from self.label(2, m.press("right", task.confirm.top(model),
                                             count=counter(task.confirm)))
        yield from self.label(2, m.hold(5))
