"""The plotly layout pieces the charts share: axes, a light layout, marker lines, notes."""


def axis(title: str, **extra) -> dict:
    return {
        "title": {"text": title},
        "gridcolor": "#e6e6e6",
        "zeroline": False,
        "showline": True,
        "linecolor": "#9e9e9e",
        "ticks": "outside",
        **extra,
    }


def base_layout(x_title: str, y_title: str, **extra) -> dict:
    """A compact, light plotly layout shared by the charts."""
    return {
        "margin": {"l": 60, "r": 12, "t": 8, "b": 42},
        "paper_bgcolor": "rgba(0,0,0,0)",
        "plot_bgcolor": "#ffffff",
        "font": {"family": "Roboto, sans-serif", "size": 11},
        "xaxis": axis(x_title),
        "yaxis": axis(y_title),
        **extra,
    }


def vline(x: float, color: str) -> dict:
    return {
        "type": "line",
        "xref": "x",
        "yref": "paper",
        "x0": x,
        "x1": x,
        "y0": 0,
        "y1": 1,
        "line": {"color": color, "width": 1.5, "dash": "longdash"},
    }


def note(text: str) -> dict:
    return {
        "text": text,
        "xref": "paper",
        "yref": "paper",
        "x": 0.5,
        "y": 0.5,
        "showarrow": False,
        "font": {"size": 13, "color": "#757575"},
    }
