"""An MIT Lincoln Laboratory Bayesian-network encounter model: reader and sampler.

A Python reading of the MATLAB sampler in ``Airspace-Encounter-Models/em-model-manned-bayes``
(BSD-2): ``em_read.m`` (the parameter file), ``bn_sample.m`` (the initial network),
``dbn_sample.m`` with ``resample_events.m`` (the dynamic network, one step a second) and
``dediscretize.m`` (a value within a bin). See docs/encounters.md.

Conventions kept from the MATLAB code: variables are numbered in the file's order, a parent
configuration is numbered column-major over the parents in increasing variable order
(``asub2ind``), counts plus a Dirichlet prior give the sampling weights (``select_random``), and a
parent configuration without any count (and a zero prior) gives the first bin, as
``select_random`` does. One convention changed: bins here are 0-based (MATLAB's bin k is bin
k - 1 here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uavxai.errors import UserError

# A hostile file is refused before anything large is allocated. The largest MIT LL file
# (haa_v1.txt) is 3.3 MB; the shipped one 0.6 MB with 2.6e5 counts.
MAX_BYTES = 4 * 1024 * 1024
MAX_VARIABLES = 32
MAX_BINS = 256
MAX_CELLS = 1_000_000  # all count tables together
_MAX_CHARS_PER_NUMBER = 32

FIELDS = (
    "labels_initial", "G_initial", "r_initial", "N_initial",
    "labels_transition", "G_transition", "r_transition", "N_transition",
    "boundaries", "resample_rates",
)


@dataclass(frozen=True)
class Network:
    """One Bayesian network: its variables, their parents, bins and counts.

    ``counts[i]`` has shape (bins[i], q_i), q_i the number of parent configurations, or is
    None for a variable that the network does not sample (the transition network's copies
    of the initial variables)."""

    labels: tuple[str, ...]
    parents: tuple[tuple[int, ...], ...]
    bins: tuple[int, ...]
    counts: tuple[np.ndarray | None, ...]
    order: tuple[int, ...]  # a topological order (MATLAB bn_sort: stable, lowest first)
    # per variable: its parents' columns and their strides (column's, computed once)
    _strides: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def column(self, i: int, state: np.ndarray) -> np.ndarray:
        """Parent configuration of variable i (asub2ind) for each row of ``state`` (n, vars):
        sum over its parents of bin x the product of the earlier parents' bin counts, as one
        integer product (exact), since a sampler asks it every second of every track."""
        if i not in self._strides:
            parents = list(self.parents[i])
            strides = np.cumprod([1] + [self.bins[p] for p in parents[:-1]], dtype=np.int64)
            self._strides[i] = (parents, strides[: len(parents)])
        parents, strides = self._strides[i]
        return state[:, parents].astype(np.int64, copy=False) @ strides


@dataclass(frozen=True)
class InitialSample:
    """n draws of the initial network: bins (0-based) and continuous values (model units)."""

    labels: tuple[str, ...]
    bins: np.ndarray  # (n, variables) int
    values: np.ndarray  # (n, variables) float


@dataclass(frozen=True)
class Transitions:
    """The dynamic variables second by second: index 0 is the initial state."""

    labels: tuple[str, ...]  # the initial network's labels of the dynamic variables
    bins: np.ndarray  # (n, seconds, dynamic variables) int
    values: np.ndarray  # (n, seconds, dynamic variables) float


@dataclass(frozen=True)
class EncounterModel:
    """A parameter file as ``em_read`` reads it (labels, graphs, bins, counts, boundaries,
    resample rates) plus the temporal map and zero bins it derives.

    ``prior`` is the Dirichlet prior added to every count: a number (the MATLAB default 0) or
    ``"dbe"`` (1 / (r q))."""

    name: str
    initial: Network
    transition: Network
    boundaries: tuple[np.ndarray | None, ...]  # per initial variable, None for '*'
    resample_rates: np.ndarray  # per initial variable, probability a second
    temporal_map: tuple[tuple[int, int], ...]  # (variable at t, variable at t+1), 0-based
    zero_bins: tuple[int | None, ...]  # the bin straddling 0, whose value is 0
    prior: float | str = 0.0
    _cumulative: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def labels(self) -> tuple[str, ...]:
        return self.initial.labels

    def index(self, label: str) -> int:
        try:
            return self.initial.labels.index(label)
        except ValueError:
            raise UserError(f"{self.name}: no variable {label!r}; "
                            f"it has {', '.join(self.initial.labels)}") from None

    # -- sampling -------------------------------------------------------------------------

    def weights(self, net: Network, i: int) -> np.ndarray:
        """Counts plus the Dirichlet prior (bn_dirichlet_prior) of variable i."""
        n = net.counts[i]
        if self.prior == "dbe":
            return n + 1.0 / n.size
        return n + float(self.prior)

    def cumulative(self, net: Network, i: int) -> np.ndarray:
        """Cumulative weights down each column, computed once per network and variable."""
        key = (net is self.transition, i)
        if key not in self._cumulative:
            self._cumulative[key] = np.cumsum(self.weights(net, i), axis=0)
        return self._cumulative[key]

    def sample_initial(self, rng: np.random.Generator, n: int,
                       start: dict[str, int] | None = None) -> InitialSample:
        """bn_sample: n ancestral draws of the initial network, then dediscretize.

        ``start`` presets bins (0-based) by label, e.g. ``{"G": 0, "A": 3, "L": 0}``; a
        preset variable's parents must be preset too (as in MATLAB)."""
        net = self.initial
        preset = {self.index(k): int(v) for k, v in (start or {}).items()}
        for i, b in preset.items():
            if not 0 <= b < net.bins[i]:
                raise UserError(f"start: {net.labels[i]} bin {b} is not in 0..{net.bins[i] - 1}")
            if any(p not in preset for p in net.parents[i]):
                raise UserError(f"start: {net.labels[i]} is preset but not all its parents")
        bins = np.zeros((n, len(net.labels)), dtype=np.int64)
        for i in net.order:
            if i in preset:
                bins[:, i] = preset[i]
            else:
                bins[:, i] = select_random(rng, self.cumulative(net, i), net.column(i, bins))
        values = np.column_stack([self.dediscretize(rng, i, bins[:, i])
                                  for i in range(len(net.labels))])
        return InitialSample(net.labels, bins, values)

    def sample_transitions(self, rng: np.random.Generator, initial: InitialSample,
                           seconds: int) -> Transitions:
        """dbn_sample + resample_events + dediscretize: step the dynamic network each second.

        Each second every dynamic variable draws its bin at t+1 given its parents at t (in the
        transition network's order); a variable whose bin changed draws a new value in it, one
        whose bin stayed redraws its value within the bin with its resample rate a second."""
        net = self.transition
        n, k = initial.bins.shape
        src = [a for a, _ in self.temporal_map]
        dst = [b for _, b in self.temporal_map]
        moving = [i for i in net.order if i in dst]
        state = np.zeros((n, len(net.labels)), dtype=np.int64)
        state[:, :k] = initial.bins
        bins = np.zeros((n, seconds, len(src)), dtype=np.int64)
        values = np.zeros((n, seconds, len(src)))
        bins[:, 0], values[:, 0] = initial.bins[:, src], initial.values[:, src]
        for t in range(1, seconds):
            for i in moving:
                state[:, i] = select_random(rng, self.cumulative(net, i), net.column(i, state))
            state[:, src] = state[:, dst]
            bins[:, t] = state[:, src]
            for m, v in enumerate(src):
                redraw = (bins[:, t, m] != bins[:, t - 1, m]) | (
                    rng.random(n) < self.resample_rates[v])
                values[:, t, m] = np.where(redraw, self.dediscretize(rng, v, bins[:, t, m]),
                                           values[:, t - 1, m])
        return Transitions(tuple(net.labels[i].removesuffix("(t)") for i in src), bins, values)

    def dediscretize(self, rng: np.random.Generator, i: int, bins: np.ndarray) -> np.ndarray:
        """dediscretize.m: a value uniform within each bin of initial variable i; the bin
        straddling zero gives 0; a variable without boundaries keeps its category number,
        1-based as the MIT LL documentation numbers them (G = 1 is CONUS)."""
        bins = np.asarray(bins, dtype=np.int64)
        edges = self.boundaries[i]
        if edges is None:
            return (bins + 1).astype(float)
        lo, hi = edges[bins], edges[bins + 1]
        x = lo + (hi - lo) * rng.random(bins.shape)
        if self.zero_bins[i] is not None:
            x = np.where(bins == self.zero_bins[i], 0.0, x)
        return x

    # -- the distribution the sampler draws from ------------------------------------------

    def conditional(self, i: int) -> np.ndarray:
        """P(variable i | parents) of the initial network, columns summing to 1; a column
        without weight puts all on bin 0 (what select_random draws there)."""
        w = self.weights(self.initial, i)
        total = w.sum(axis=0)
        p = np.divide(w, total, out=np.zeros_like(w), where=total > 0)
        p[0, total <= 0] = 1.0
        return p

    def initial_marginals(self) -> list[np.ndarray]:
        """Exact marginal of each initial variable, by enumerating the network's joint
        P(x) = prod_i P(x_i | parents_i) (refused above 1e7 joint states)."""
        net = self.initial
        if math.prod(net.bins) > 10_000_000:
            raise UserError(f"{self.name}: too many joint states to enumerate")
        joint = np.ones(net.bins)  # axis i = variable i
        grids = np.indices(net.bins).reshape(len(net.bins), -1).T  # (states, vars)
        flat = joint.reshape(-1)
        for i in net.order:
            flat *= self.conditional(i)[grids[:, i], net.column(i, grids)]
        others = lambda i: tuple(a for a in range(len(net.bins)) if a != i)  # noqa: E731
        return [joint.sum(axis=others(i)) for i in range(len(net.bins))]


def select_random(rng: np.random.Generator, cumulative: np.ndarray,
                  columns: np.ndarray) -> np.ndarray:
    """select_random.m for many draws: in column ``columns[k]`` of the cumulative weights
    (bins, q), the first bin whose cumulative weight reaches u * total, u uniform in [0, 1)."""
    cum = cumulative[:, columns]
    threshold = cum[-1] * rng.random(len(columns))
    return (cum < threshold).sum(axis=0)


# -- reading a parameter file ---------------------------------------------------------------


def load_model(path: str | Path) -> EncounterModel:
    """Read an MIT LL parameter file (em_read's format); a malformed or hostile file raises
    UserError naming the problem, before anything larger than the file is allocated."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise UserError(f"{path}: {size} bytes, more than the {MAX_BYTES} an encounter "
                            "model parameter file may have")
        with path.open("rb") as f:
            raw = f.read(MAX_BYTES + 1)
    except OSError as e:
        raise UserError(f"cannot read encounter model {path}: {e}") from None
    if len(raw) > MAX_BYTES:
        raise UserError(f"{path}: more than {MAX_BYTES} bytes")
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise UserError(f"{path}: not an ASCII encounter model parameter file") from None
    return parse_model(text, name=path.name)


def parse_model(text: str, name: str = "model") -> EncounterModel:
    """Parse the text of a parameter file (see load_model)."""
    blocks = _blocks(text, name)
    labels_i = _labels(blocks["labels_initial"], name, "labels_initial")
    labels_t = _labels(blocks["labels_transition"], name, "labels_transition")
    k = len(labels_i)
    if tuple(s.removesuffix("(t)") for s in labels_t[:k]) != labels_i:
        raise UserError(f"{name}: labels_transition must start with labels_initial")
    initial = _network(blocks, "initial", labels_i, range(k), name)
    transition = _network(blocks, "transition", labels_t, range(k, len(labels_t)), name)
    if transition.bins[:k] != initial.bins:
        raise UserError(f"{name}: r_transition must start with r_initial")
    cells = sum(c.size for c in initial.counts + transition.counts if c is not None)
    if cells > MAX_CELLS:
        raise UserError(f"{name}: {cells} counts, more than {MAX_CELLS}")
    temporal = _temporal_map(labels_t, name)
    for a, b in temporal:
        if transition.bins[a] != transition.bins[b]:
            raise UserError(f"{name}: {labels_t[a]} and {labels_t[b]} have different bins")
    boundaries = _boundaries(blocks["boundaries"], initial.bins, name)
    rates = _numbers(blocks["resample_rates"], k, name, "resample_rates")
    if np.any((rates < 0) | (rates > 1)):
        raise UserError(f"{name}: resample_rates must be probabilities in [0, 1]")
    return EncounterModel(name, initial, transition, boundaries, rates, temporal,
                          tuple(_zero_bin(b) for b in boundaries))


def _blocks(text: str, name: str) -> dict[str, list[str]]:
    blocks: dict[str, list[str]] = {}
    current = None
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("#"):
            current = line.lstrip("#").strip()
            if current not in FIELDS:
                raise UserError(f"{name}: unknown field {current!r}; expected {', '.join(FIELDS)}")
            if current in blocks:
                raise UserError(f"{name}: field {current!r} appears twice")
            blocks[current] = []
        elif line:
            if current is None:
                raise UserError(f"{name}: data before the first '# field' header")
            blocks[current].append(line)
    missing = [f for f in FIELDS if f not in blocks]
    if missing:
        raise UserError(f"{name}: missing fields {', '.join(missing)}")
    return blocks


def _labels(lines: list[str], name: str, field: str) -> tuple[str, ...]:
    if len(lines) != 1:
        raise UserError(f"{name}: {field} must be one line")
    labels = tuple(s.strip().strip('"') for s in lines[0].split(","))
    if not 0 < len(labels) <= MAX_VARIABLES or any(not s or len(s) > 64 for s in labels):
        raise UserError(f"{name}: {field} must name 1..{MAX_VARIABLES} variables")
    if len(set(labels)) != len(labels):
        raise UserError(f"{name}: {field} repeats a label")
    return labels


def _numbers(lines: list[str], count: int, name: str, field: str) -> np.ndarray:
    """Exactly ``count`` finite numbers on one line (length checked before splitting)."""
    if len(lines) != 1:
        raise UserError(f"{name}: {field} must be one line")
    if len(lines[0]) > _MAX_CHARS_PER_NUMBER * count + 64:
        raise UserError(f"{name}: {field} is longer than {count} numbers can be")
    words = lines[0].split()
    if len(words) != count:
        raise UserError(f"{name}: {field} has {len(words)} numbers, expected {count}")
    try:
        x = np.array([float(w) for w in words])
    except ValueError as e:
        raise UserError(f"{name}: {field}: {e}") from None
    if not np.all(np.isfinite(x)):
        raise UserError(f"{name}: {field} has a NaN or infinite number")
    return x


def _network(blocks: dict[str, list[str]], which: str, labels: tuple[str, ...],
             sampled: range, name: str) -> Network:
    n = len(labels)
    rows = blocks[f"G_{which}"]
    if len(rows) != n:
        raise UserError(f"{name}: G_{which} must have {n} rows")
    graph = np.array([_numbers([r], n, name, f"G_{which}") for r in rows])
    if not np.all((graph == 0) | (graph == 1)):
        raise UserError(f"{name}: G_{which} must hold only 0 and 1")
    r = _numbers(blocks[f"r_{which}"], n, name, f"r_{which}")
    if np.any(r != np.round(r)) or np.any(r < 1) or np.any(r > MAX_BINS):
        raise UserError(f"{name}: r_{which} must be whole numbers of bins in 1..{MAX_BINS}")
    bins = tuple(int(b) for b in r)
    order = _topological_order(graph, name)
    parents = tuple(tuple(int(p) for p in np.flatnonzero(graph[:, i])) for i in range(n))
    dims = {}
    for i in sampled:
        q = 1
        for p in parents[i]:
            q *= bins[p]
            if q * bins[i] > MAX_CELLS:
                raise UserError(f"{name}: {labels[i]} would need more than {MAX_CELLS} counts")
        dims[i] = (bins[i], q)
    total = sum(a * b for a, b in dims.values())
    if total > MAX_CELLS:
        raise UserError(f"{name}: N_{which} would need {total} counts, more than {MAX_CELLS}")
    flat = _numbers(blocks[f"N_{which}"], total, name, f"N_{which}")
    if np.any(flat < 0):
        raise UserError(f"{name}: N_{which} has a negative count")
    counts: list[np.ndarray | None] = [None] * n
    at = 0
    for i, (ri, q) in dims.items():
        counts[i] = flat[at:at + ri * q].reshape((ri, q), order="F")
        at += ri * q
    return Network(labels, parents, bins, tuple(counts), order)


def _topological_order(graph: np.ndarray, name: str) -> tuple[int, ...]:
    """Kahn's algorithm taking the lowest ready variable first (toposort 'stable')."""
    indegree = graph.sum(axis=0).astype(int)
    done: list[int] = []
    ready = [i for i in range(len(graph)) if indegree[i] == 0]
    while ready:
        i = min(ready)
        ready.remove(i)
        done.append(i)
        for c in np.flatnonzero(graph[i]):
            indegree[c] -= 1
            if indegree[c] == 0:
                ready.append(int(c))
    if len(done) != len(graph):
        raise UserError(f"{name}: the network has a cycle")
    return tuple(done)


def _temporal_map(labels: tuple[str, ...], name: str) -> tuple[tuple[int, int], ...]:
    pairs = []
    for i, s in enumerate(labels):
        if s.endswith("(t)"):
            nxt = s[:-3] + "(t+1)"
            if nxt in labels:
                pairs.append((i, labels.index(nxt)))
    if not pairs:
        raise UserError(f"{name}: no dynamic variable (a label 'x(t)' with an 'x(t+1)')")
    return tuple(pairs)


def _boundaries(lines: list[str], bins: tuple[int, ...], name: str
                ) -> tuple[np.ndarray | None, ...]:
    if len(lines) != len(bins):
        raise UserError(f"{name}: boundaries must have one line per initial variable")
    out: list[np.ndarray | None] = []
    for line, r in zip(lines, bins, strict=True):
        if line == "*":
            out.append(None)
            continue
        edges = _numbers([line], r + 1, name, "boundaries")
        if np.any(np.diff(edges) <= 0):
            raise UserError(f"{name}: boundaries must increase")
        out.append(edges)
    return tuple(out)


def _zero_bin(edges: np.ndarray | None) -> int | None:
    """extract_zero_bins: the bin whose lower edge is negative and upper edge positive."""
    if edges is None or len(edges) <= 2:
        return None
    found = [j for j in range(len(edges) - 1) if edges[j] < 0 < edges[j + 1]]
    return found[-1] if found else None


def default_model_path() -> Path:
    return Path(__file__).resolve().parent / "data" / "uncor_1200only_fwse_v1p2.txt"


def default_model() -> EncounterModel:
    """The shipped model (data/README.md says which and why)."""
    return load_model(default_model_path())
