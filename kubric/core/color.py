"""Colours: linear RGBA floats in [0, 1].

``Color`` is an immutable 4-tuple ``(r, g, b, a)``. Build one from floats, a hex string (``"#rgb"``,
``"#rgba"``, ``"#rrggbb"``, ``"#rrggbbaa"``; the ``#`` is optional), HSV(A) or a CSS colour name
(the W3C list, 148 names). Any value outside [0, 1] is a ``ValueError`` naming it.
The values are passed to the renderer as they are (no gamma is applied).
"""

from __future__ import annotations

import colorsys

import numpy as np

#: W3C CSS colour names (CSS Color Module Level 4), name:rrggbb.
_CSS_NAMES = (
    "aliceblue:f0f8ff antiquewhite:faebd7 aqua:00ffff aquamarine:7fffd4 azure:f0ffff beige:f5f5dc "
    "bisque:ffe4c4 black:000000 blanchedalmond:ffebcd blue:0000ff blueviolet:8a2be2 brown:a52a2a "
    "burlywood:deb887 cadetblue:5f9ea0 chartreuse:7fff00 chocolate:d2691e coral:ff7f50 "
    "cornflowerblue:6495ed cornsilk:fff8dc crimson:dc143c cyan:00ffff darkblue:00008b darkcyan:008b8b "
    "darkgoldenrod:b8860b darkgray:a9a9a9 darkgreen:006400 darkgrey:a9a9a9 darkkhaki:bdb76b "
    "darkmagenta:8b008b darkolivegreen:556b2f darkorange:ff8c00 darkorchid:9932cc darkred:8b0000 "
    "darksalmon:e9967a darkseagreen:8fbc8f darkslateblue:483d8b darkslategray:2f4f4f "
    "darkslategrey:2f4f4f darkturquoise:00ced1 darkviolet:9400d3 deeppink:ff1493 deepskyblue:00bfff "
    "dimgray:696969 dimgrey:696969 dodgerblue:1e90ff firebrick:b22222 floralwhite:fffaf0 "
    "forestgreen:228b22 fuchsia:ff00ff gainsboro:dcdcdc ghostwhite:f8f8ff gold:ffd700 "
    "goldenrod:daa520 gray:808080 green:008000 greenyellow:adff2f grey:808080 honeydew:f0fff0 "
    "hotpink:ff69b4 indianred:cd5c5c indigo:4b0082 ivory:fffff0 khaki:f0e68c lavender:e6e6fa "
    "lavenderblush:fff0f5 lawngreen:7cfc00 lemonchiffon:fffacd lightblue:add8e6 lightcoral:f08080 "
    "lightcyan:e0ffff lightgoldenrodyellow:fafad2 lightgray:d3d3d3 lightgreen:90ee90 lightgrey:d3d3d3 "
    "lightpink:ffb6c1 lightsalmon:ffa07a lightseagreen:20b2aa lightskyblue:87cefa "
    "lightslategray:778899 lightslategrey:778899 lightsteelblue:b0c4de lightyellow:ffffe0 lime:00ff00 "
    "limegreen:32cd32 linen:faf0e6 magenta:ff00ff maroon:800000 mediumaquamarine:66cdaa "
    "mediumblue:0000cd mediumorchid:ba55d3 mediumpurple:9370db mediumseagreen:3cb371 "
    "mediumslateblue:7b68ee mediumspringgreen:00fa9a mediumturquoise:48d1cc mediumvioletred:c71585 "
    "midnightblue:191970 mintcream:f5fffa mistyrose:ffe4e1 moccasin:ffe4b5 navajowhite:ffdead "
    "navy:000080 oldlace:fdf5e6 olive:808000 olivedrab:6b8e23 orange:ffa500 orangered:ff4500 "
    "orchid:da70d6 palegoldenrod:eee8aa palegreen:98fb98 paleturquoise:afeeee palevioletred:db7093 "
    "papayawhip:ffefd5 peachpuff:ffdab9 peru:cd853f pink:ffc0cb plum:dda0dd powderblue:b0e0e6 "
    "purple:800080 rebeccapurple:663399 red:ff0000 rosybrown:bc8f8f royalblue:4169e1 "
    "saddlebrown:8b4513 salmon:fa8072 sandybrown:f4a460 seagreen:2e8b57 seashell:fff5ee sienna:a0522d "
    "silver:c0c0c0 skyblue:87ceeb slateblue:6a5acd slategray:708090 slategrey:708090 snow:fffafa "
    "springgreen:00ff7f steelblue:4682b4 tan:d2b48c teal:008080 thistle:d8bfd8 tomato:ff6347 "
    "turquoise:40e0d0 violet:ee82ee wheat:f5deb3 white:ffffff whitesmoke:f5f5f5 yellow:ffff00 "
    "yellowgreen:9acd32 "
)
CSS_COLORS: dict[str, str] = dict(item.split(":") for item in _CSS_NAMES.split())


class Color(tuple):
    """An RGBA colour with components in [0, 1]; alpha defaults to 1."""

    __slots__ = ()

    def __new__(cls, r: float = 0.0, g: float = 0.0, b: float = 0.0, a: float = 1.0):
        values = []
        for label, v in zip("rgba", (r, g, b, a), strict=True):
            if isinstance(v, bool) or np.ndim(v) != 0:
                raise TypeError(f"Color.{label} must be a number in [0, 1], got {v!r}")
            f = float(v)
            if not 0.0 <= f <= 1.0:
                raise ValueError(f"Color.{label} must be in [0, 1], got {v!r}")
            values.append(f)
        return super().__new__(cls, values)

    def __getnewargs__(self) -> tuple[float, float, float, float]:
        # pickle / copy rebuild a tuple subclass by calling __new__ with these arguments; without
        # this they would pass the whole tuple as ``r``
        return tuple(self)

    r = property(lambda self: self[0])
    g = property(lambda self: self[1])
    b = property(lambda self: self[2])
    a = property(lambda self: self[3])

    @property
    def rgb(self) -> tuple[float, float, float]:
        return self[0], self[1], self[2]

    @property
    def rgba(self) -> tuple[float, float, float, float]:
        return tuple(self)

    @property
    def hsv(self) -> tuple[float, float, float]:
        return colorsys.rgb_to_hsv(*self.rgb)

    @property
    def hexstr(self) -> str:
        """``"#rrggbbaa"``."""
        return "#" + "".join(f"{int(round(v * 255)):02x}" for v in self)

    @property
    def hexstr_short(self) -> str:
        """``"#rgba"``: one hex digit per channel, alpha included (upstream Kubric's short form).

        Each channel is rounded to the nearest of the 16 levels 0, 1/15, ..., 1, so a colour read
        from a short string (``from_hexstr("#f0c")``) gives that string back (``"#f0cf"``)."""
        return "#" + "".join(f"{int(round(v * 15)):x}" for v in self)

    def __repr__(self) -> str:
        return "Color(r={:.4g}, g={:.4g}, b={:.4g}, a={:.4g})".format(*self)

    @classmethod
    def from_hexstr(cls, hexstr: str) -> Color:
        s = hexstr[1:] if hexstr.startswith("#") else hexstr
        if len(s) not in (3, 4, 6, 8) or any(c not in "0123456789abcdefABCDEF" for c in s):
            raise ValueError(f"hex colour must have 3, 4, 6 or 8 hex digits, got {hexstr!r}")
        if len(s) in (3, 4):
            s = "".join(c * 2 for c in s)
        vals = [int(s[i:i + 2], 16) / 255.0 for i in range(0, len(s), 2)]
        return cls(*vals)

    @classmethod
    def from_hexint(cls, hexint: int, alpha: float = 1.0) -> Color:
        """From an integer ``0xRRGGBB``."""
        if isinstance(hexint, bool) or not isinstance(hexint, (int, np.integer)) \
                or not 0 <= int(hexint) <= 0xFFFFFF:
            raise ValueError(f"hex integer colour must be in [0, 0xFFFFFF], got {hexint!r}")
        v = int(hexint)
        return cls(((v >> 16) & 255) / 255.0, ((v >> 8) & 255) / 255.0, (v & 255) / 255.0, alpha)

    @classmethod
    def from_hsv(cls, h: float, s: float, v: float, alpha: float = 1.0) -> Color:
        for label, x in zip("hsv", (h, s, v), strict=True):
            if not 0.0 <= float(x) <= 1.0:
                raise ValueError(f"HSV component {label} must be in [0, 1], got {x!r}")
        return cls(*colorsys.hsv_to_rgb(h, s, v), alpha)

    @classmethod
    def from_name(cls, name: str) -> Color:
        key = name.lower().replace(" ", "").replace("_", "")
        if key not in CSS_COLORS:
            close = [n for n in CSS_COLORS if n.startswith(key[:3])][:5]
            hint = f"; did you mean {close}?" if close else ""
            raise ValueError(f"unknown colour name {name!r} (CSS colour names are allowed){hint}")
        return cls.from_hexstr(CSS_COLORS[key])


def get_color(color) -> Color:
    """A :class:`Color` from a Color, a CSS name, a hex string, an int ``0xRRGGBB`` or 3–4 floats
    in [0, 1]."""
    if isinstance(color, Color):
        return color
    if isinstance(color, (int, np.integer)) and not isinstance(color, bool):
        return Color.from_hexint(color)
    if isinstance(color, str):
        if color.startswith("#") or (len(color) in (3, 4, 6, 8)
                                     and all(c in "0123456789abcdefABCDEF" for c in color)
                                     and color.lower() not in CSS_COLORS):
            return Color.from_hexstr(color)
        return Color.from_name(color)
    try:
        values = [float(v) for v in np.asarray(color, dtype=np.float64).reshape(-1)]
    except (TypeError, ValueError):
        raise TypeError(f"cannot make a colour from {color!r}") from None
    if len(values) not in (3, 4):
        raise ValueError(f"a colour needs 3 or 4 components in [0, 1], got {color!r}")
    return Color(*values)


def srgb_to_linear(srgb) -> np.ndarray:
    """sRGB-encoded values in [0, 1] → linear values (IEC 61966-2-1; inputs clipped to [0, 1])."""
    c = np.clip(np.asarray(srgb, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear) -> np.ndarray:
    """Linear values in [0, 1] → sRGB-encoded values in [0, 1] (inputs clipped to [0, 1])."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
