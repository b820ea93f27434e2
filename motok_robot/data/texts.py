"""Natural-language descriptions for every clip, and left/right swapping for mirrored clips.

* Bandai Namco: content x style -> several sentences ("a person walks forward happily");
* CMU: the trial description from ``cmu-descriptions.csv`` (by ``SS_TT``), also used for
  DeepMimic's converted CMU trials;
* DeepMimic: the clip name (``humanoid3d_spinkick`` -> "a person does a spinning kick");
* acRNN: the genre folder (salsa, indian, martial);
* any data: a user text index (CSV ``key,text`` rows or JSON ``{key: text | [texts]}``).

Sentence choice is deterministic per clip id (a hash of the id seeds the choice).
"""

from __future__ import annotations

import csv
import hashlib
import random
import re
from pathlib import Path

from motok_robot.config_utils import read_json_object
from motok_robot.errors import InputError

SUBJECTS = ("a person", "someone", "the person", "a human", "a figure")

# ----------------------------------------------------------------------------- Bandai
#: content -> verb phrases (third person)
BANDAI_CONTENT = {
    "walk": ("walks forward", "walks ahead", "takes a walk forward", "walks straight ahead"),
    "walk-left": ("walks to the left", "walks toward the left side", "moves to the left while walking"),
    "walk-right": ("walks to the right", "walks toward the right side", "moves to the right while walking"),
    "walk-back": ("walks backward", "walks backwards", "steps back several times"),
    "walk-turn-left": ("walks and turns left", "walks forward and then turns to the left", "turns left while walking"),
    "walk-turn-right": ("walks and turns right", "walks forward and then turns to the right", "turns right while walking"),
    "run": ("runs forward", "jogs ahead", "runs"),
    "dash": ("dashes forward", "sprints ahead", "runs forward at full speed"),
    "guide": ("gestures to show someone the way", "points the way with an arm", "guides someone with a hand gesture"),
    "bow": ("bows", "bows to someone", "bends forward in a bow"),
    "bye": ("waves goodbye", "waves a hand to say goodbye", "says goodbye with a wave"),
    "byebye": ("waves bye-bye", "waves goodbye repeatedly", "says bye-bye with a waving hand"),
    "call": ("calls out to someone", "calls someone over", "beckons to someone"),
    "respond": ("responds to someone", "answers someone who called", "reacts to being called"),
    "punch": ("throws a punch", "punches", "punches forward"),
    "kick": ("kicks", "throws a kick", "kicks forward"),
    "slash": ("makes a slashing motion", "slashes with an arm", "swings an arm as if slashing with a sword"),
    "dance-short": ("dances", "does a short dance", "dances in place"),
    "dance-long": ("dances", "performs a long dance", "dances for a while"),
    "raise-up-left-hand": ("raises the left hand", "lifts the left hand up", "puts the left hand up"),
    "raise-up-right-hand": ("raises the right hand", "lifts the right hand up", "puts the right hand up"),
    "raise-up-both-hands": ("raises both hands", "lifts both hands up", "puts both hands up"),
    "wave-left-hand": ("waves the left hand", "waves with the left hand", "waves using the left hand"),
    "wave-right-hand": ("waves the right hand", "waves with the right hand", "waves using the right hand"),
    "wave-both-hands": ("waves both hands", "waves with both hands", "waves both hands in the air"),
}
#: style -> (adverbs, adjectives describing the person); "normal" adds no style words
BANDAI_STYLE = {
    "normal": ((), ()),
    "happy": (("happily", "cheerfully", "joyfully"), ("happy", "cheerful")),
    "sad": (("sadly", "gloomily", "dejectedly"), ("sad", "gloomy")),
    "angry": (("angrily", "furiously"), ("angry", "furious")),
    "proud": (("proudly", "with pride", "confidently with the chest out"), ("proud",)),
    "tired": (("tiredly", "wearily", "sluggishly"), ("tired", "weary")),
    "exhausted": (("in an exhausted way", "wearily", "with great fatigue"), ("exhausted", "worn-out")),
    "old": (("like an old person", "slowly like an elderly person", "stiffly like an old person"), ("old", "elderly")),
    "elderly": (("like an elderly person", "slowly like an old person", "stiffly like an elderly person"), ("elderly", "old")),
    "giant": (("like a giant", "heavily like a giant", "with big heavy movements"), ("giant", "huge")),
    "childish": (("childishly", "like a child", "playfully like a child"), ("childish", "playful")),
    "youthful": (("youthfully", "with youthful energy", "like a young person"), ("youthful", "young")),
    "feminine": (("in a feminine way", "femininely", "with feminine movements"), ("feminine",)),
    "masculinity": (("in a masculine way", "masculinely", "with masculine movements"), ("masculine",)),
    "masculine": (("in a masculine way", "masculinely", "with masculine movements"), ("masculine",)),
    "musical": (("in a musical way", "rhythmically like in a musical", "theatrically as in a musical"), ("theatrical",)),
    "not-confident": (("timidly", "without confidence", "hesitantly"), ("timid", "unconfident")),
    "active": (("energetically", "actively", "vigorously"), ("energetic", "lively")),
    "chimpira": (("like a thug", "with a delinquent swagger", "in a thuggish way"), ("thuggish", "swaggering")),
}


def _rng(key: str) -> random.Random:
    return random.Random(int(hashlib.sha256(key.encode()).hexdigest()[:16], 16))


def bandai_texts(content: str, style: str, clip_id: str, n: int = 4) -> list[str]:
    """``n`` distinct sentences for a Bandai content x style take; raises InputError if unknown."""
    if content not in BANDAI_CONTENT:
        raise InputError(f"{clip_id}: unknown Bandai content {content!r}")
    if style not in BANDAI_STYLE:
        raise InputError(f"{clip_id}: unknown Bandai style {style!r}")
    rng = _rng(clip_id)
    verbs = BANDAI_CONTENT[content]
    advs, adjs = BANDAI_STYLE[style]
    out: list[str] = []
    for _ in range(8 * n):
        if len(out) >= n:
            break
        subj, vp = rng.choice(SUBJECTS), rng.choice(verbs)
        if not advs:
            form = rng.randrange(2)
            s = f"{subj} {vp}" if form == 0 else f"{subj} {vp} in a normal way"
        else:
            form = rng.randrange(3)
            if form == 0:
                s = f"{subj} {vp} {rng.choice(advs)}"
            elif form == 1:
                adj = rng.choice(adjs)
                art = "an" if adj[0] in "aeiou" else "a"
                s = f"{art} {adj} person {vp}"
            else:
                s = f"{rng.choice(advs)}, {subj} {vp}"
        s = s[0].upper() + s[1:] + "."
        if s not in out:
            out.append(s)
    return out


# ----------------------------------------------------------------------------- CMU
_CMU_VERBS = {
    "walk": "walks", "run": "runs", "jog": "jogs", "jump": "jumps", "hop": "hops", "climb": "climbs",
    "dance": "dances", "kick": "kicks", "punch": "punches", "sit": "sits", "stand": "stands",
    "turn": "turns", "swing": "swings", "hang": "hangs", "throw": "throws", "catch": "catches",
    "wave": "waves", "stretch": "stretches", "step": "steps", "skip": "skips", "balance": "balances",
    "bend": "bends", "box": "boxes", "march": "marches", "crawl": "crawls", "roll": "rolls",
    "spin": "spins", "stumble": "stumbles", "sneak": "sneaks", "salsa": "dances salsa", "bow": "bows",
    "lean": "leans", "reach": "reaches", "pick": "picks", "push": "pushes", "pull": "pulls",
    "shuffle": "shuffles", "twist": "twists", "swim": "swims", "fall": "falls", "get": "gets",
    "look": "looks", "wash": "washes", "sweep": "sweeps", "lift": "lifts", "carry": "carries",
    "drink": "drinks", "eat": "eats", "play": "plays", "navigate": "navigates", "mop": "mops",
    "cartwheel": "does a cartwheel", "backflip": "does a backflip", "somersault": "does a somersault",
}


def load_cmu_descriptions(csv_path: str | Path) -> dict[str, dict]:
    """``{"SS_TT": {"description": str, "fps": float | None}}`` from the CMU descriptions CSV."""
    path = Path(csv_path)
    out: dict[str, dict] = {}
    try:
        with path.open(newline="", encoding="utf-8", errors="replace") as fh:
            for row in csv.DictReader(fh):
                try:
                    s, t = int(row["Subject"]), int(row["Trial #"])
                except (KeyError, TypeError, ValueError):
                    continue
                fps = None
                try:
                    fps = float(row.get("framerate") or "") or None
                except ValueError:
                    pass
                out[f"{s:02d}_{t:02d}"] = {"description": (row.get("Motion Description") or "").strip(), "fps": fps}
    except OSError as exc:
        raise InputError(f"{path}: cannot read CMU descriptions ({exc})") from None
    return out


_AFTER_VERB = {"on", "in", "to", "up", "down", "forward", "forwards", "backward", "backwards", "around", "right",
               "left", "with", "over", "across", "away", "fast", "slowly", "quickly", "in-place", "sideways", "back",
               "from", "into", "onto", "off", "out", "through", "along", "while", "like", "at", "straight", "normally",
               "the", "a", "an", "both", "one", "hands", "arms", "legs"}


def _conjugate(phrase: str) -> str | None:
    """Third-person form of a verb phrase ("walk on uneven terrain" -> "walks on uneven terrain"),
    or None when the phrase does not clearly start with a known verb ("jump twist" is a noun)."""
    words = phrase.split()
    if not words or (len(words) > 1 and words[1].lower().strip(",") not in _AFTER_VERB):
        return None
    w = words[0].lower().rstrip(",")
    for base, third in _CMU_VERBS.items():
        if w == base or w == base + "s":
            return " ".join([third] + words[1:])
        if w.endswith("ing") and w[:-3] in (base, base.rstrip("e")):
            return " ".join([third] + words[1:])
        if w.endswith("ing") and len(w) > 5 and w[:-4] == base and w[-4] == w[-5]:  # running, jogging
            return " ".join([third] + words[1:])
    return None


_COUNTABLE = {"jump", "kick", "punch", "turn", "flip", "cartwheel", "twist", "spin", "roll", "step", "walk", "run",
              "dance", "hop", "leap", "bow", "wave", "throw", "stretch", "squat", "lunge", "handstand", "somersault"}


def _noun_sentence(desc: str) -> str:
    """"forward jump" -> "A person performs a forward jump."; "swordplay" -> "A person performs swordplay."."""
    words = desc.split()
    last = words[-1].lower() if words else ""
    art = ""
    if last in _COUNTABLE:
        art = "an " if desc[0].lower() in "aeiou" else "a "
    return f"A person performs {art}{desc}."


def description_texts(description: str, clip_id: str) -> list[str]:
    """Sentences from a free-form motion description ("run/jog", "walk on uneven terrain")."""
    desc = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", description.strip())  # "JumpTwist" -> "Jump Twist"
    desc = re.sub(r"\s+", " ", desc.strip(".").strip())
    if desc and desc != desc.upper():
        desc = desc[0] + desc[1:].lower() if " " in desc and desc.split()[0].istitle() else desc
    if not desc:
        return []
    rng = _rng(clip_id)
    out: list[str] = []
    head, _, tail = desc.partition(" - ")  # "playground - forward jumps, turn around"
    parts = [p.strip() for p in re.split(r"[/,;]| - ", desc) if p.strip()]
    for p in [desc] + parts:
        vp = _conjugate(p)
        if vp:
            s = f"{rng.choice(SUBJECTS)} {vp}"
            out.append(s[0].upper() + s[1:] + ".")
    if not out:
        out.append(_noun_sentence(desc[0].lower() + desc[1:]))
    out.append(desc[0].upper() + desc[1:] + ".")
    seen, uniq = set(), []
    for s in out:
        if s.lower() not in seen:
            seen.add(s.lower())
            uniq.append(s)
    return uniq


# ----------------------------------------------------------------------------- DeepMimic
DEEPMIMIC_NAMES = {
    "backflip": ("does a backflip", "flips backward in the air", "performs a back somersault"),
    "sideflip": ("does a side flip", "flips sideways in the air", "performs an aerial side flip"),
    "cartwheel": ("does a cartwheel", "cartwheels to the side", "turns a cartwheel"),
    "crawl": ("crawls on hands and knees", "crawls forward", "moves forward on all fours"),
    "roll": ("does a forward roll", "rolls on the ground", "tumbles forward in a roll"),
    "spinkick": ("does a spinning kick", "spins around and kicks", "performs a spin kick"),
    "spin": ("spins around", "turns around in place", "does a full spin"),
    "dance_spin": ("dances and spins around", "does a dance with a spin", "spins while dancing"),
    "dance_a": ("dances", "does a dance", "dances energetically"),
    "dance_b": ("dances", "performs a dance routine", "dances with arm movements"),
    "getup_faceup": ("gets up from lying on the back", "stands up after lying face up", "rises from the floor on the back"),
    "getup_facedown": ("gets up from lying face down", "pushes up from the floor and stands", "rises from lying on the stomach"),
    "stealthy_walk": ("walks stealthily", "sneaks forward quietly", "tiptoes forward carefully"),
    "zombie_walk": ("walks like a zombie", "shambles forward like a zombie", "staggers forward with arms out like a zombie"),
    "zombie": ("walks like a zombie", "shambles around like a zombie", "staggers like a zombie"),
    "run_jump": ("runs and jumps", "runs forward and leaps", "takes a running jump"),
    "run_roll": ("runs and rolls", "runs forward and does a roll", "runs then tumbles into a roll"),
    "bridge": ("does a backbend bridge", "bends backward into a bridge", "arches back into a bridge pose"),
    "long_walk": ("walks around", "walks for a long time", "keeps walking and turning"),
    "walk": ("walks forward", "walks", "walks at a normal pace"),
    "jog": ("jogs forward", "jogs", "runs at a slow pace"),
    "run": ("runs forward", "runs", "runs quickly"),
    "jump": ("jumps", "jumps forward", "leaps into the air"),
    "kick": ("kicks", "kicks forward", "throws a kick"),
    "punch": ("punches", "throws a punch", "punches forward"),
}


def deepmimic_texts(name: str, clip_id: str, n: int = 3) -> list[str]:
    """Sentences from a DeepMimic clip name (``humanoid3d_long_walk2_mirror`` -> long walk)."""
    key = name.lower()
    key = re.sub(r"^humanoid3d_", "", key)
    key = re.sub(r"_mirror$", "", key)
    key = re.sub(r"\d+$", "", key).rstrip("_")
    match = None
    for k in sorted(DEEPMIMIC_NAMES, key=len, reverse=True):
        if key == k or key.endswith(k) or k in key:
            match = k
            break
    if match is None:
        words = key.replace("_", " ").strip()
        return [f"A person performs a {words} motion."] if re.search(r"[a-z]{3}", words) else []
    rng = _rng(clip_id)
    phrases = list(DEEPMIMIC_NAMES[match])
    rng.shuffle(phrases)
    return [(f"{rng.choice(SUBJECTS)} {p}.").capitalize() for p in phrases[:n]]


# ----------------------------------------------------------------------------- acRNN
ACRNN_GENRES = {
    "salsa": ("dances salsa", "performs salsa dance steps", "does a salsa dance"),
    "indian": ("performs an Indian dance", "does a classical Indian dance", "dances an Indian dance"),
    "martial": ("practises martial arts moves", "performs martial arts", "does a martial arts routine"),
}


def acrnn_texts(genre: str, clip_id: str) -> list[str]:
    if genre not in ACRNN_GENRES:
        return [f"A person performs {genre.replace('_', ' ')}."]
    rng = _rng(clip_id)
    return [f"{rng.choice(SUBJECTS)} {p}.".capitalize().replace("indian", "Indian") for p in ACRNN_GENRES[genre]]


# ----------------------------------------------------------------------------- user index

def load_text_index(path: str | Path) -> dict[str, list[str]]:
    """User text index: ``{key: [texts]}``; keys match a clip id, file name, stem or relative path.

    CSV: a header with a key column (``file``, ``clip``, ``id`` or ``path``) and a ``text``
    column, one row per sentence.  JSON: ``{key: "text" | ["text", ...]}``.
    """
    path = Path(path)
    out: dict[str, list[str]] = {}
    if path.suffix.lower() == ".json":
        raw = read_json_object(path, "text index")
        for k, v in raw.items():
            vals = [v] if isinstance(v, str) else v
            if not isinstance(vals, list) or not all(isinstance(s, str) for s in vals):
                raise InputError(f"{path}: entry {k!r} must be a string or a list of strings")
            out.setdefault(str(k), []).extend(s.strip() for s in vals if s.strip())
        return out
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            cols = [c.lower().strip() for c in (reader.fieldnames or [])]
            key_col = next((c for c in ("file", "clip", "id", "path") if c in cols), None)
            if key_col is None or "text" not in cols:
                raise InputError(f"{path}: CSV text index needs a 'file' (or clip/id/path) column and a 'text' column; has {cols}")
            names = {c.lower().strip(): c for c in reader.fieldnames or []}
            for row in reader:
                k, t = (row.get(names[key_col]) or "").strip(), (row.get(names["text"]) or "").strip()
                if k and t:
                    out.setdefault(k, []).append(t)
    except OSError as exc:
        raise InputError(f"{path}: cannot read text index ({exc})") from None
    return out


def lookup_texts(index: dict[str, list[str]], clip_id: str, file: str) -> list[str]:
    """Texts for a clip from a user index (by clip id, file path suffix, file name or stem)."""
    name = file.split(":")[-1]
    stem = Path(name).stem
    for key in (clip_id, clip_id.split("/", 1)[-1], name, Path(name).name, stem):
        if key in index:
            return list(index[key])
    for key, vals in index.items():  # relative path given in the index
        if "/" in key and name.endswith(key):
            return list(vals)
    return []


# ----------------------------------------------------------------------------- mirroring
_SWAPS = (
    ("left", "right"),
    ("leftward", "rightward"),
    ("leftwards", "rightwards"),
    ("counterclockwise", "clockwise"),
    ("anticlockwise", "clockwise"),
    ("counter-clockwise", "clockwise"),
)
_SWAP_MAP: dict[str, str] = {}
for _a, _b in _SWAPS:
    _SWAP_MAP.setdefault(_a, _b)
    _SWAP_MAP.setdefault(_b, _a)
_SWAP_RE = re.compile(r"\b(" + "|".join(sorted(map(re.escape, _SWAP_MAP), key=len, reverse=True)) + r")\b", re.IGNORECASE)
# "right" that does not mean a side: leave alone
_NOT_SIDE = re.compile(r"\b(all right|right away|right now|right after|right before|right back|right there|right here)\b", re.I)


def mirror_text(text: str) -> str:
    """Swap left/right words (and clockwise/counterclockwise) keeping capitalisation.

    "turns left" -> "turns right", "left hand" -> "right hand"; idioms such as "right away"
    keep their "right".
    """
    protected = {}

    def protect(m: re.Match) -> str:
        key = f"\x00{len(protected)}\x00"
        protected[key] = m.group(0)
        return key

    t = _NOT_SIDE.sub(protect, text)

    def swap(m: re.Match) -> str:
        w = m.group(0)
        r = _SWAP_MAP[w.lower()]
        if w.isupper():
            return r.upper()
        if w[0].isupper():
            return r[0].upper() + r[1:]
        return r

    t = _SWAP_RE.sub(swap, t)
    for k, v in protected.items():
        t = t.replace(k, v)
    return t
