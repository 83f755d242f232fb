"""95% intervals for success rates measured over a finite number of episodes.

A cell of 100 episodes at 20% has a Wilson 95% interval of about 13-29%: two cells 3 points
apart are usually the same policy. Every rate rmbench reports carries its interval, and every
comparison of two cells carries the interval of their difference.

- ``wilson``: the Wilson score interval for one binomial rate (keeps inside [0, 1] and stays
  informative at 0/100 and 100/100, where the normal approximation collapses to a point).
- ``difference``: Newcombe's hybrid score interval (method 10) for the difference of two
  independent rates, built from the two Wilson intervals.
- ``paired_difference``: Newcombe's score interval for the difference of two rates measured
  on the same episodes (method 10 of his paired-data paper), from the four pair counts.
- ``format_difference``: a difference and its interval in points, as the docs print them.
- ``share``: a count out of a total as results files store it, with its interval.
"""

from __future__ import annotations

import math

Z95 = 1.959963984540054  # the standard normal's 97.5% quantile


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """(low, high) of the Wilson score interval for ``successes`` out of ``n``, as fractions."""
    if n <= 0:
        raise ValueError(f"an interval needs at least one episode, got n={n}")
    if not 0 <= successes <= n:
        raise ValueError(f"successes={successes} outside [0, n={n}]")
    p = successes / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    # The exact ends are 0 and 1 at 0/n and n/n; rounding must not leave them a hair inside.
    low = 0.0 if successes == 0 else max(0.0, centre - half)
    high = 1.0 if successes == n else min(1.0, centre + half)
    return low, high


def ci95(count: int, of: int) -> list[float] | None:
    """The Wilson 95% interval of ``count`` out of ``of`` as the results files store it:
    fractions to 4 places, None where there is nothing to count."""
    return [round(v, 4) for v in wilson(count, of)] if of else None


def share(count: int, of: int) -> dict:
    """{count, of, rate, ci95}: a count out of a total as the results files store it, the rate
    and its Wilson interval as fractions (both None where there is nothing to count)."""
    return {"count": count, "of": of, "rate": round(count / of, 4) if of else None,
            "ci95": ci95(count, of)}


def difference(k1: int, n1: int, k2: int, n2: int, z: float = Z95) -> tuple[float, float, float]:
    """(d, low, high) for d = k1/n1 - k2/n2, Newcombe's hybrid score interval, as fractions."""
    p1, p2 = k1 / n1 if n1 else 0.0, k2 / n2 if n2 else 0.0
    return _combined(p1, wilson(k1, n1, z), p2, wilson(k2, n2, z))


def _combined(p1: float, ci1: tuple[float, float], p2: float, ci2: tuple[float, float],
              phi: float = 0.0) -> tuple[float, float, float]:
    """Newcombe's square-and-add: (p1 - p2, low, high) from each rate's Wilson interval, the
    two rates' correlation ``phi`` taken out (0 for independent samples)."""
    (l1, u1), (l2, u2) = ci1, ci2
    d = p1 - p2
    low = d - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2)
                            + (u2 - p2) ** 2))
    high = d + math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2)
                             + (p2 - l2) ** 2))
    return d, max(-1.0, low), min(1.0, high)


def paired_difference(both: int, first_only: int, second_only: int, n: int,
                      z: float = Z95) -> tuple[float, float, float]:
    """(d, low, high) for d = (both + first_only)/n - (both + second_only)/n, two rates over
    the same ``n`` episodes (each seed run both ways): Newcombe's 1998 paired score interval
    (method 10), ``difference``'s two Wilson intervals combined with the pairs' phi
    correlation. Outcomes that mostly agree make it narrower than the independent one."""
    neither = n - both - first_only - second_only
    if min(both, first_only, second_only, neither) < 0:
        raise ValueError(f"pair counts {both}, {first_only}, {second_only} exceed n={n}")
    k1, k2 = both + first_only, both + second_only
    margins = k1 * (n - k1) * k2 * (n - k2)
    phi = (both * neither - first_only * second_only) / math.sqrt(margins) if margins else 0.0
    return _combined(k1 / n, wilson(k1, n, z), k2 / n, wilson(k2, n, z), phi)


def outside_noise(k1: int, n1: int, k2: int, n2: int, z: float = Z95) -> bool:
    """True when the difference's 95% interval excludes zero."""
    _, low, high = difference(k1, n1, k2, n2, z)
    return low > 0 or high < 0


def format_rate(successes: int, n: int) -> str:
    """'20 [13, 29]': the rate and its 95% interval in percent, as the docs print them."""
    low, high = wilson(successes, n)
    return f"{100 * successes / n:.0f} [{100 * low:.0f}, {100 * high:.0f}]"


def signed(points: float, digits: int = 0) -> str:
    """'+5', '-18', '0': ``points`` rounded to ``digits`` decimals with its sign, and without
    one where it rounds to zero ("-0" would put a zero on one side of it). A value a float
    holds a hair off a tie (151/200 - 68/100 as 7.4999999999999991 points) is its exact
    value first, so it rounds as the rates it comes from do."""
    text = f"{round(points, 9):+.{digits}f}"
    return text[1:] if float(text) == 0 else text


def format_difference(d: float, low: float, high: float, digits: int = 0) -> str:
    """'+66 [+54, +75]', '-9 [-18, -0.2]': a difference of two rates and its 95% interval,
    given as fractions, in points. An end that is not zero keeps a decimal more until it reads
    so: an interval that excludes zero never prints one as its end."""
    return (f"{signed(100 * d, digits)} [{_end(100 * low, digits)}, "
            f"{_end(100 * high, digits)}]")


def _end(points: float, digits: int) -> str:
    text = signed(points, digits)
    while float(text) == 0 and round(points, 9) != 0 and digits < 3:
        digits += 1
        text = signed(points, digits)
    return text
