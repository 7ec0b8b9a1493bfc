"""
DOF layout of the flexible four-bar (Cho, Park & Lee 1992, Fig. 3 and Eq. 25).

Each modelled link is a chain of beam elements in its moving frame. Interior nodes keep
moving-frame DOFs (u, v, phi); the end nodes at the joints carry ground-frame translations
(X, Y) and their own rotation phi. Joints are exact pins (members share X, Y; separate
rotations; fixed at O2 and O4) or isotropic bearing springs k (Eq. 23) between the members'
own end nodes. The input shaft is clamped (crank rotation at O2 fixed) or a torsional spring
k_t. With a rigid crank, crank pin A is a fixed point of the frozen structure (a flexible
bearing at A then ties the coupler's end to that point).

:func:`number_dofs` numbers the DOFs once (a :class:`DofMap`); :func:`gather_matrix` is the
link's T^T of Eq. 25 (``u^L = T^T U``) and its derivatives in the link angle.
"""

import dataclasses

import numpy as np

from ..mechanism import JOINT_MEMBERS
from ...names import JOINT_NAMES
from ...names import LINK_NAMES

# First joint of each link: the link frame's x runs from it to the link's second joint.
FIRST_JOINT = {0: 'O2', 1: 'A', 2: 'O4'}
# Local DOF labels of a node, in order.
NODE_LABELS = ('u', 'v', 'phi')


@dataclasses.dataclass(frozen=True)
class DofMap:
    """
    System DOFs of a modelled linkage.

    Attributes
    ----------
    names : tuple of str
        Name of each DOF ('A.X', 'coupler.n1.v', 'B.lever.phi', ...).
    gather : dict of int to ndarray of int, shape (3 (e + 1),)
        Per link, the system index of each local DOF (node-major u, v, phi; -1 = fixed).
    end_nodes : dict of int to tuple
        Per link, (local u index, system X index, system Y index) of each ground-frame end node.
    end_masses : dict of int to tuple of float
        Per link, point masses [kg] at its first and last node (joint mass shares).
    bearing_stiffness : ndarray, shape (n, n)
        Bearing springs (Eq. 23) and the shaft spring k_t.

    """

    names: tuple
    gather: dict
    end_nodes: dict
    end_masses: dict
    bearing_stiffness: np.ndarray

    @property
    def size(self):
        """Return the number of system DOFs n."""
        return len(self.names)

    def index(self, name):
        """Index of the DOF called ``name``."""
        return self.names.index(name)


def end_index(link, joint):
    """Return 0 if ``joint`` is the link's first joint, 1 if its second."""
    return 0 if joint == FIRST_JOINT[link] else 1


class _Numbering:
    """Mutable state while DOFs are numbered joint by joint, then link by link."""

    def __init__(self, links, elements):
        self.names = []
        self.gather = {link: -np.ones(3 * (elements + 1), dtype=int) for link in links}
        self.end_nodes = {link: [] for link in links}
        self.end_mass = {link: [0.0, 0.0] for link in links}
        self.springs = []
        self.elements = elements

    def new(self, name):
        """Append a DOF called ``name`` and return its index."""
        self.names.append(name)
        return len(self.names) - 1

    def translations(self, joint, members, mechanism, flexible, grounded):
        """Assign the (X, Y) pair of every member at ``joint``; None where it is fixed."""
        mass = mechanism.joint_masses.get(joint, 0.0)
        if not flexible:
            shared = None if grounded else (self.new(f'{joint}.X'), self.new(f'{joint}.Y'))
            if members:
                self.end_mass[members[0]][end_index(members[0], joint)] += mass
            return [shared] * len(members)
        pairs = [(self.new(f'{joint}.{LINK_NAMES[m]}.X'), self.new(f'{joint}.{LINK_NAMES[m]}.Y'))
                 for m in members]
        shares = dict(zip(JOINT_MEMBERS[joint],
                          (mechanism.joint_mass_split, 1.0 - mechanism.joint_mass_split)))
        for m in members:
            self.end_mass[m][end_index(m, joint)] += shares[m] * mass
        if grounded:
            self.springs.extend((pair, None) for pair in pairs)
        elif len(pairs) == 2:
            self.springs.append((pairs[0], pairs[1]))
        return pairs

    def joint(self, joint, links, mechanism, options):
        """Assign the end-node DOFs of every modelled member at ``joint``."""
        members = [m for m in JOINT_MEMBERS[joint] if m in links]
        grounded = -1 in JOINT_MEMBERS[joint] or (joint == 'A' and options.rigid_crank)
        flexible = options.bearings == 'flexible' and joint in mechanism.bearing_joints
        pairs = self.translations(joint, members, mechanism, flexible, grounded)
        for m, pair in zip(members, pairs):
            node = 0 if end_index(m, joint) == 0 else self.elements
            if pair is not None:
                self.gather[m][3 * node:3 * node + 2] = pair
                self.end_nodes[m].append((3 * node, pair[0], pair[1]))
            clamped = joint == 'O2' and m == 0 and mechanism.shaft_stiffness is None
            if not clamped:
                self.gather[m][3 * node + 2] = self.new(f'{joint}.{LINK_NAMES[m]}.phi')

    def interior(self, link):
        """Assign the moving-frame (u, v, phi) DOFs of a link's interior nodes."""
        for node in range(1, self.elements):
            for c, label in enumerate(NODE_LABELS):
                self.gather[link][3 * node + c] = self.new(f'{LINK_NAMES[link]}.n{node}.{label}')


def bearing_matrix(size, springs, stiffness, shaft=None):
    """
    Bearing springs (Eq. 23) and the input-shaft spring as a system matrix.

    Parameters
    ----------
    size : int
        Number of system DOFs n.
    springs : list of tuple
        ((X, Y) of one member, (X, Y) of the other or None for a grounded spring).
    stiffness : float
        Isotropic bearing stiffness k [N/m].
    shaft : tuple or None
        (crank rotation DOF at O2, k_t [N m/rad]) of a torsional shaft spring.

    Returns
    -------
    ndarray, shape (n, n)

    """
    k_bearing = np.zeros((size, size))
    for first, second in springs:
        for i in range(2):
            k_bearing[first[i], first[i]] += stiffness
            if second is not None:
                k_bearing[second[i], second[i]] += stiffness
                k_bearing[first[i], second[i]] -= stiffness
                k_bearing[second[i], first[i]] -= stiffness
    if shaft is not None:
        phi, k_shaft = shaft
        k_bearing[phi, phi] += k_shaft
    return k_bearing


def number_dofs(mechanism, options, links):
    """
    Assign the system DOFs: joint end nodes first (in joint order), then interior nodes.

    Parameters
    ----------
    mechanism : Mechanism
        Needs ``elements_per_link``; ``bearing_stiffness`` for flexible bearings.
    options : ModelOptions
        ``rigid_crank`` and ``bearings`` are read.
    links : tuple of int
        Modelled links (0 crank, 1 coupler, 2 lever).

    Returns
    -------
    DofMap

    """
    numbering = _Numbering(links, mechanism.elements_per_link)
    for joint in JOINT_NAMES:
        numbering.joint(joint, links, mechanism, options)
    for link in links:
        numbering.interior(link)
    shaft = None
    if 0 in links and mechanism.shaft_stiffness is not None:
        shaft = (numbering.gather[0][2], mechanism.shaft_stiffness)
    k_bearing = bearing_matrix(len(numbering.names), numbering.springs,
                               mechanism.bearing_stiffness or 0.0, shaft)
    return DofMap(names=tuple(numbering.names), gather=numbering.gather,
                  end_nodes={link: tuple(nodes) for link, nodes in numbering.end_nodes.items()},
                  end_masses={link: tuple(m) for link, m in numbering.end_mass.items()},
                  bearing_stiffness=k_bearing)


def gather_matrix(dofs, link, link_angle, order=0):
    """
    T^T of a link (Eq. 25) or its derivative in theta_L, at N link angles.

    Parameters
    ----------
    dofs : DofMap
        The DOF layout (:func:`number_dofs`).
    link : int
        A modelled link.
    link_angle : ndarray, shape (N,)
        theta_L [rad].
    order : int
        0 for T^T, 1 for dT^T/dtheta_L, 2 for d^2T^T/dtheta_L^2.

    Returns
    -------
    ndarray, shape (N, 3 (e + 1), n)

    """
    angle = np.atleast_1d(np.asarray(link_angle, dtype=float))
    gather = dofs.gather[link]
    out = np.zeros((angle.shape[0], gather.shape[0], dofs.size))
    if order == 0:
        rows = np.flatnonzero(gather >= 0)
        out[:, rows, gather[rows]] = 1.0
    c, s = np.cos(angle), np.sin(angle)
    # u_local = R^T U_ground and its derivatives in theta (R^T = [[c, s], [-s, c]])
    block = {0: ((c, s), (-s, c)), 1: ((-s, c), (-c, -s)), 2: ((-c, -s), (s, -c))}[order]
    for row, gx, gy in dofs.end_nodes[link]:
        out[:, row, gx], out[:, row, gy] = block[0]
        out[:, row + 1, gx], out[:, row + 1, gy] = block[1]
    return out
