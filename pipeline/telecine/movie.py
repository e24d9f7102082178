"""Movies from EXR sequences with PyAV: a documented view transform, professional defaults.

View transform (no OCIO config): scene-linear RGB is scaled by 2**exposure, clipped to
[0, 1] and encoded with the sRGB curve (IEC 61966-2-1), alpha dropped (our frames are
premultiplied over black). With an OCIO config (needs the PyOpenColorIO package) the
exposure-scaled pixels go through the config's display/view transform instead (a config
file or a built-in one, `ocio://cg-config-latest`; see `ViewTransform`). The
result is quantised to 16 bits and handed to FFmpeg's `scale` filter for the conversion
to the codec's Y'CbCr (BT.709 matrix, video range); for interlaced output the filter
subsamples chroma per field (`interl=1`), and `setfield` marks the field order on every
frame so the encoder and the container record it.

Codecs: `prores` (prores_ks, profile HQ, 4:2:2 10-bit, .mov) is the delivery default,
`h264` (libx264, CRF 18, 4:2:0 8-bit, .mp4) the review default; the extension chooses
when no codec is given. Files are encoded to a hidden temporary name and renamed.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping

import numpy as np

from ..deliverables import PLAIN_VIEW
from ..errors import FrameIOError, UsageError
from ..write_policy import writing
from ..timeline import rate_label
from ..field_model import FieldOrder, check_field_order
from .sequence import Sequence, discover, read_mapped

Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class Codec:
    """An FFmpeg encoder with its pixel format and options."""

    encoder: str
    pix_fmt: str
    options: Mapping[str, str] = field(default_factory=dict)
    container: str = "mov"


CODECS: dict[str, Codec] = {
    # ProRes 422 HQ: prores_ks profile 3; vendor apl0 is what Apple's decoders expect.
    "prores": Codec("prores_ks", "yuv422p10le", {"profile": "3", "vendor": "apl0"}, "mov"),
    "prores4444": Codec("prores_ks", "yuva444p10le", {"profile": "4", "vendor": "apl0"}, "mov"),
    "h264": Codec("libx264", "yuv420p", {"crf": "18", "preset": "medium"}, "mp4"),
}
DEFAULT_FOR_SUFFIX = {".mov": "prores", ".mp4": "h264", ".m4v": "h264", ".mkv": "h264"}
CONTAINER_FOR_SUFFIX = {".mov": "mov", ".mp4": "mp4", ".m4v": "mp4", ".mkv": "matroska"}

# FFmpeg's AVFieldOrder values (libavcodec/defs.h): what the container's field atom records.
AV_FIELD_PROGRESSIVE, AV_FIELD_TT, AV_FIELD_BB = 1, 2, 3


def choose_codec(path: str | Path, codec: str | None = None) -> tuple[Codec, str]:
    """The codec for a movie path (explicit name, or from its extension) and the container."""
    suffix = Path(path).suffix.lower()
    if suffix not in CONTAINER_FOR_SUFFIX:
        raise UsageError(f"{path}: unknown movie extension {suffix!r} (use .mov, .mp4 or .mkv)")
    name = codec or DEFAULT_FOR_SUFFIX[suffix]
    if name not in CODECS:
        raise UsageError(f"unknown codec {name!r}: expected one of {', '.join(CODECS)}")
    chosen = CODECS[name]
    if chosen.encoder == "prores_ks" and suffix == ".mp4":
        raise UsageError(f"{path}: ProRes goes in a .mov, not an .mp4")
    return chosen, CONTAINER_FOR_SUFFIX[suffix]


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on values clipped to [0, 1]."""
    x = np.clip(linear, 0.0, 1.0)
    # IEC 61966-2-1: 12.92 x below 0.0031308, else 1.055 x^(1/2.4) - 0.055.
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


# Colour tags (AVColorPrimaries, AVColorTransferCharacteristic) of the displays we can name;
# any other OCIO display is tagged "unspecified" (2, 2) rather than guessed.
BT709, TRC_BT709, TRC_GAMMA22, TRC_SRGB, UNSPECIFIED = 1, 1, 4, 13, 2
_DISPLAY_TAGS: tuple[tuple[str, tuple[int, int]], ...] = (
    ("srgb", (BT709, TRC_SRGB)),
    ("rec.1886 rec.709", (BT709, TRC_BT709)),
    ("gamma 2.2 rec.709", (BT709, TRC_GAMMA22)),
)
# Our renders are linear Rec.709 (Mitsuba's RGB variants). Aliases of that colour space in the
# ACES built-in configs (cg/studio) and in common studio configs, tried in this order.
LINEAR_REC709_NAMES = ("lin_rec709_srgb", "lin_rec709", "Linear Rec.709 (sRGB)", "lin_srgb", "Utility - Linear - sRGB")


def builtin_ocio_configs() -> list[str]:
    """Names of the OCIO configs built into the installed PyOpenColorIO (use as ocio://NAME)."""
    import PyOpenColorIO as OCIO  # type: ignore[import-not-found]

    return list(OCIO.BuiltinConfigRegistry())


MAX_EXPOSURE_STOPS = 32  # x 4e9 either way: past that every pixel is black or white
DEFAULT_VIEW_CONFIG = "ocio://cg-config-latest"  # its default view: ACES 2.0 - SDR 100 nits (Rec.709) on sRGB


class ViewTransform:
    """Scene-linear RGBA -> display-referred RGB uint16 [H, W, 3].

    By default (no config named) OpenColorIO's built-in CG config and its default view,
    ACES 2.0 SDR on an sRGB display: a tone curve that rolls highlights off instead of
    clipping them (a bright sky keeps its colour). `ocio_config="none"`: x 2**exposure,
    clip to [0, 1], sRGB curve. With a config (a file or a built-in URI such as
    ``ocio://studio-config-latest``): x 2**exposure, then the config's
    DisplayViewTransform from `ocio_colorspace` (default: the config's linear Rec.709
    colour space if it has one, else its ``scene_linear`` role) to `ocio_display` /
    `ocio_view` (defaults: the config's default display and that display's default view),
    then clip to [0, 1].
    """

    def __init__(
        self,
        exposure: float = 0.0,
        ocio_config: str | Path | None = None,
        ocio_display: str | None = None,
        ocio_view: str | None = None,
        ocio_colorspace: str | None = None,
    ) -> None:
        if not (isinstance(exposure, (int, float)) and math.isfinite(exposure) and abs(exposure) <= MAX_EXPOSURE_STOPS):
            raise UsageError(f"--exposure {exposure}: expected a finite number of stops from {-MAX_EXPOSURE_STOPS} to {MAX_EXPOSURE_STOPS}")
        self.gain = np.float32(2.0 ** float(exposure))
        self._cpu = None
        self.display = self.view = self.source = None
        self.color_tags = (BT709, TRC_SRGB)  # (primaries, transfer) for the movie's stream
        self.description = f"linear -> sRGB, exposure {float(exposure):+g} stops"
        if ocio_config is None:
            ocio_config = DEFAULT_VIEW_CONFIG
        if str(ocio_config).strip().lower() in PLAIN_VIEW:
            if ocio_display or ocio_view or ocio_colorspace:
                raise UsageError("--ocio-display/--ocio-view/--ocio-colorspace need an OCIO config (--ocio), not --ocio none")
            return
        try:
            import PyOpenColorIO as OCIO  # type: ignore[import-not-found]
        except ImportError:
            raise UsageError(
                f"an OCIO config was given ({ocio_config}) but the PyOpenColorIO package is not "
                "installed (pip install opencolorio), or omit --ocio for the built-in sRGB view"
            ) from None
        # str, not Path: pathlib would turn ocio://name into ocio:/name.
        name = str(ocio_config)
        if not name.startswith("ocio://"):  # a FIFO or a device hung OCIO's reader: a regular file only
            from ..limits import MAX_OCIO_CONFIG_BYTES, open_bounded

            open_bounded(name, MAX_OCIO_CONFIG_BYTES, "OCIO config", UsageError).close()
        try:
            config = OCIO.Config.CreateFromFile(name)
        except Exception as exc:  # OCIO raises its own Exception type for any bad config
            hint = ""
            if name.startswith("ocio://"):
                hint = f"; built-in configs: ocio://default, ocio://cg-config-latest, ocio://studio-config-latest, " \
                       f"or ocio://NAME with NAME one of {', '.join(builtin_ocio_configs())}"
            raise UsageError(f"{name}: OCIO config unusable ({exc}){hint}") from None
        displays = list(config.getDisplays())
        display = ocio_display or config.getDefaultDisplay()
        if display not in displays:
            raise UsageError(f"{name}: no OCIO display {display!r}; the config has {', '.join(displays)}")
        views = list(config.getViews(display))
        view = ocio_view or config.getDefaultView(display)
        if view not in views:
            raise UsageError(f"{name}: display {display!r} has no view {view!r}; it has {', '.join(views)}")
        if ocio_colorspace is not None:
            cs = config.getColorSpace(ocio_colorspace)
            if cs is None:
                raise UsageError(f"{name}: no OCIO colour space {ocio_colorspace!r}")
            source = cs.getName()
        else:
            found = next((config.getColorSpace(n) for n in LINEAR_REC709_NAMES if config.getColorSpace(n)), None)
            source = found.getName() if found is not None else config.getColorSpace(OCIO.ROLE_SCENE_LINEAR).getName()
        try:
            transform = OCIO.DisplayViewTransform(src=source, display=display, view=view)
            self._cpu = config.getProcessor(transform).getDefaultCPUProcessor()
        except Exception as exc:
            raise UsageError(f"{name}: OCIO cannot build {source} -> {display}/{view} ({exc})") from None
        self.display, self.view, self.source = display, view, source
        self.color_tags = next((tags for key, tags in _DISPLAY_TAGS if key in display.lower()),
                               (UNSPECIFIED, UNSPECIFIED))
        self.description = f"OCIO {name}: {source} -> {display} / {view}, exposure {float(exposure):+g}"

    def encode(self, rgba: np.ndarray) -> np.ndarray:
        """Display-referred float RGB in [0, 1], [..., 3] (before quantisation)."""
        rgb = np.ascontiguousarray(rgba[..., :3], dtype=np.float32) * self.gain
        if self._cpu is None:
            return srgb_encode(rgb)
        flat = np.ascontiguousarray(rgb.reshape(-1, 3))
        self._cpu.applyRGB(flat)
        return np.clip(flat.reshape(rgb.shape), 0.0, 1.0)

    def __call__(self, rgba: np.ndarray) -> np.ndarray:
        return np.round(self.encode(rgba) * 65535.0).astype(np.uint16)




class ViewedFrames:
    """The viewed frames (display-referred RGB uint16, `view(rgba)`) of one sequence, kept
    while they fit a byte budget and shared by the deliverables made from it in one run:
    the 24p movie, the 60i pulldown (which views each film frame as it reads it for the
    field frames) and the 60i movie view each frame once between them, not once each.
    A frame past the budget is viewed again when asked for; the pixels are the same
    either way (the view is a pure function of the frame)."""

    def __init__(self, seq: Sequence, view: ViewTransform, budget_bytes: int | None = None) -> None:
        if budget_bytes is None:
            from ..limits import env_size

            budget_bytes = env_size("MOTION_VIEWED_MB") << 20
        self.paths, self.view, self.budget = seq.paths, view, budget_bytes
        self.kept: dict[int, np.ndarray] = {}
        self.used = 0

    def serves(self, seq: Sequence, view: ViewTransform) -> bool:
        """Whether these are the frames of `seq` (position for position) under `view`."""
        return seq.paths == self.paths and view is self.view

    def keep(self, index: int, rgb16: np.ndarray) -> np.ndarray:
        """Keep frame `index`'s viewed pixels while they fit the budget; returns them."""
        if index not in self.kept and self.used + rgb16.nbytes <= self.budget:
            self.kept[index] = rgb16
            self.used += rgb16.nbytes
        return rgb16


def viewed(seq: Sequence, view: ViewTransform, indices: Iterable[int] | None = None, shared: ViewedFrames | None = None) -> Iterator[np.ndarray]:
    """`view(frame.rgba)` of frames `indices` (0-based, default all) in order: those
    `shared` keeps as kept, the others read and viewed side by side on the cores
    (sequence.read_mapped) and kept there when they fit."""
    order = list(range(len(seq)) if indices is None else indices)
    if shared is None or not shared.serves(seq, view):
        yield from read_mapped(seq, lambda frame: view(frame.rgba), order)
        return
    missing = [i for i in order if i not in shared.kept]
    made = zip(missing, read_mapped(seq, lambda frame: view(frame.rgba), missing))
    for i in order:
        if i in shared.kept:
            yield shared.kept[i]
        else:
            index, rgb16 = next(made)
            yield shared.keep(index, rgb16)


class _Encoder:
    """One video stream: RGB48 frames -> scale/format/setfield filter graph -> encoder -> muxer."""

    def __init__(self, path: Path, container: str, codec: Codec, width: int, height: int, rate: Fraction,
                 field_order: FieldOrder | None, timecode: str | None,
                 color_tags: tuple[int, int] = (BT709, TRC_SRGB), comment: str | None = None) -> None:
        import av

        self.av = av
        if codec.pix_fmt.startswith("yuv4") and (width % 2 or (codec.pix_fmt.startswith("yuv420") and height % 2)):
            raise FrameIOError(f"{path}: {width}x{height} cannot be encoded as {codec.pix_fmt} (odd size)")
        self.out = av.open(str(path), "w", format=container)
        if timecode:
            self.out.metadata["timecode"] = timecode
        if comment:
            self.out.metadata["comment"] = comment  # what a player's info panel shows
        options = dict(codec.options)
        if field_order and codec.encoder == "libx264":
            options["x264-params"] = f"{field_order}=1"  # x264 takes the field order at open
        self.stream = self.out.add_stream(codec.encoder, rate=rate, options=options)
        self.stream.width, self.stream.height, self.stream.pix_fmt = width, height, codec.pix_fmt
        cc = self.stream.codec_context
        cc.time_base = 1 / rate
        if field_order:
            from av.codec.context import Flags

            cc.flags |= Flags.interlaced_dct | Flags.interlaced_me
            cc.field_order = AV_FIELD_TT if field_order == "tff" else AV_FIELD_BB
        else:
            cc.field_order = AV_FIELD_PROGRESSIVE
        # BT.709 matrix, video range; primaries and transfer from the view transform (sRGB by default).
        cc.color_primaries, cc.color_trc = color_tags
        cc.colorspace, cc.color_range = 1, 1
        self.time_base = 1 / rate
        self.graph = av.filter.Graph()
        self.src = self.graph.add(
            "buffer",
            f"video_size={width}x{height}:pix_fmt=rgb48le:time_base={self.time_base.numerator}/"
            f"{self.time_base.denominator}:frame_rate={rate.numerator}/{rate.denominator}:pixel_aspect=1/1",
        )
        chain = [
            self.graph.add("scale", f"out_color_matrix=bt709:out_range=tv:interl={1 if field_order else 0}"),
            self.graph.add("format", codec.pix_fmt),
            self.graph.add("setfield", field_order or "prog"),
            self.graph.add("buffersink"),
        ]
        node = self.src
        for nxt in chain:
            node.link_to(nxt)
            node = nxt
        self.sink = chain[-1]
        self.graph.configure()
        self.count = 0

    def _drain(self) -> None:
        av = self.av
        while True:
            try:
                frame = self.sink.pull()
            except (av.BlockingIOError, av.EOFError):
                return
            for packet in self.stream.encode(frame):
                self.out.mux(packet)

    def add(self, rgb16: np.ndarray) -> None:
        frame = self.av.VideoFrame.from_ndarray(rgb16, format="rgb48le")
        frame.pts, frame.time_base = self.count, self.time_base
        self.count += 1
        self.src.push(frame)
        self._drain()

    def close(self) -> None:
        self.src.push(None)
        self._drain()
        for packet in self.stream.encode():
            self.out.mux(packet)
        self.out.close()


def write_movie(
    path: str | Path,
    frames: Iterable[np.ndarray],
    rate: Fraction,
    *,
    width: int,
    height: int,
    codec: str | None = None,
    field_order: str | None = None,
    view: ViewTransform | None = None,
    timecode: str | None = None,
    progress: Progress | None = None,
    total: int = 0,
) -> Path:
    """Encode linear RGBA frames into a movie at `rate`; interlaced when `field_order` is given.

    Written through the write policy (write_policy.writing): a hidden temporary file next to `path`,
    renamed when complete; a full disk is one DiskFaultError line.
    """
    path = Path(path)
    chosen, container = choose_codec(path, codec)
    order = check_field_order(field_order) if field_order else None
    view = view or ViewTransform()
    return encode_movie(path, chosen, container, (view(rgba) for rgba in frames), rate, width, height, order, view, timecode, progress, total)


def encode_movie(path: Path, chosen: Codec, container: str, frames: Iterable[np.ndarray], rate: Fraction, width: int, height: int,
            order: FieldOrder | None, view: ViewTransform, timecode: str | None, progress: Progress | None, total: int) -> Path:
    """Encode display-referred RGB uint16 frames [H, W, 3] (`view` already applied; it
    names the movie's colour tags and comment) into a movie, through the write policy."""
    with writing(path, "writing the movie", suffix=path.suffix + ".part") as tmp:
        # the rate named as it plays ('23.976 fps (24000/1001)'), the scan and the view, in the file
        scan = f"interlaced {order}" if order else "progressive"
        comment = f"{rate_label(Fraction(rate))}, {scan}; view: {view.description}"
        encoder = _Encoder(tmp, container, chosen, width, height, Fraction(rate), order, timecode,
                           view.color_tags, comment)
        for i, rgb16 in enumerate(frames):
            encoder.add(rgb16)
            if progress:
                progress(i + 1, total)
        encoder.close()
    return path


def sequence_movie(
    in_dir: str | Path | Sequence,
    path: str | Path,
    *,
    rate: Fraction | None = None,
    field_order: str | None = "auto",
    codec: str | None = None,
    view: ViewTransform | None = None,
    prefix: str | None = None,
    progress: Progress | None = None,
    shared: ViewedFrames | None = None,
) -> Path:
    """A movie of an EXR sequence (`shared`: viewed frames a run's deliverables share).

    `rate` defaults to the frames' `framesPerSecond`; `field_order="auto"` takes the
    frames' `motion:fieldOrder` (tff/bff -> interlaced, anything else progressive);
    None forces progressive.
    """
    seq = in_dir if isinstance(in_dir, Sequence) else discover(in_dir, prefix, require_even_height=False)
    rate = Fraction(rate) if rate is not None else seq.fps
    if rate is None:
        raise UsageError(f"{seq.paths[0]}: no framesPerSecond in the header; give the movie rate")
    if field_order == "auto":
        meta_order = seq.first_meta.get("fieldOrder")
        field_order = meta_order if meta_order in ("tff", "bff") else None
    if field_order and seq.height % 2:
        raise FrameIOError(f"{seq.paths[0]}: odd height {seq.height}; interlaced fields need an even number of rows")
    path = Path(path)
    chosen, container = choose_codec(path, codec)
    order = check_field_order(field_order) if field_order else None
    view = view or ViewTransform()
    # each frame read and viewed once (or taken from those the run's deliverables share), side by side on the cores, encoded in order
    frames = viewed(seq, view, shared=shared)
    return encode_movie(path, chosen, container, frames, rate, seq.width, seq.height, order, view, first_timecode(seq), progress, len(seq))


def first_timecode(seq: Sequence) -> str | None:
    """The sequence's first frame's `timeCode` attribute as HH:MM:SS:FF (None without one):
    the movie's timecode track starts there, so the movie and its frames agree."""
    from ..frame_output import header_timecode, read_header

    return header_timecode(read_header(seq.paths[0]))
