"""Integer nanoseconds <-> builtin_interfaces Time / Duration, with range checks.

Times in this package are plain Python ``int`` nanoseconds (no float rounding). A ROS stamp
``(sec: int32, nanosec: uint32)`` holds ``sec * 1e9 + nanosec`` with ``0 <= nanosec < 1e9``.
"""
import operator

from builtin_interfaces.msg import Duration, Time

NS_PER_S = 1_000_000_000
INT32_MAX = 2 ** 31 - 1


def as_int(value, what):
    """``value`` as an exact Python int (numpy integers accepted; floats and bools refused)."""
    if isinstance(value, bool):
        raise TypeError(f'{what} must be an integer, got a bool')
    try:
        return operator.index(value)
    except TypeError:
        raise TypeError(f'{what} must be an integer, got {type(value).__name__} '
                        f'{value!r}') from None


def split_ns(t_ns, what='stamp_ns'):
    """Non-negative nanoseconds -> ``(sec, nanosec)`` Python ints that fit a ROS Time/Duration."""
    t_ns = as_int(t_ns, what)
    if t_ns < 0:
        raise ValueError(f'{what} must be >= 0 ns, got {t_ns}')
    sec, nanosec = divmod(t_ns, NS_PER_S)
    if sec > INT32_MAX:
        raise ValueError(f'{what} = {t_ns} ns does not fit a ROS stamp (sec is int32)')
    return sec, nanosec


def time_msg(t_ns, what='stamp_ns'):
    """builtin_interfaces/Time of ``t_ns`` nanoseconds (0 stays 0)."""
    sec, nanosec = split_ns(t_ns, what)
    return Time(sec=sec, nanosec=nanosec)


def duration_msg(ns, what='duration_ns'):
    """builtin_interfaces/Duration of ``ns`` >= 0 nanoseconds (0 means 'forever' for markers)."""
    sec, nanosec = split_ns(ns, what)
    return Duration(sec=sec, nanosec=nanosec)


def time_to_ns(stamp, what='header.stamp'):
    """Nanoseconds of a Time-like ``stamp`` (``.sec``, ``.nanosec``); ValueError names the field.

    Refuses negative seconds and ``nanosec >= 1e9`` (not a normalised stamp).
    """
    sec = as_int(stamp.sec, f'{what}.sec')
    nanosec = as_int(stamp.nanosec, f'{what}.nanosec')
    if sec < 0:
        raise ValueError(f'{what}.sec is {sec}: stamps before 1970 (negative) are not accepted')
    if not 0 <= nanosec < NS_PER_S:
        raise ValueError(f'{what}.nanosec is {nanosec}: must be in [0, 1e9)')
    return sec * NS_PER_S + nanosec
