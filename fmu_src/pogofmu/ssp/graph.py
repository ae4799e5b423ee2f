"""The update order of a system and its algebraic loops, from the FMUs' declared dependencies.

An output that depends *directly* on an input (the FMU's ``ModelStructure``: ``dependencies`` of
the output lists the input; an output without the attribute depends on every input, as the
standard says) makes its component wait for the component that feeds the input: Gauss–Seidel,
the initialization and the event iteration update the feeding component first. A cycle of such
dependencies through the connections is an algebraic loop.
"""
from __future__ import annotations

from typing import Dict, List, Optional, Set, Tuple


def feedthrough(comp) -> Dict[str, Optional[Set[str]]]:
    """``{output: inputs it depends on directly}`` of one component (None: every input)."""
    md = comp.model_description
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    out = {}
    for unknown in md.outputs:
        deps = unknown.dependencies
        out[unknown.variable.name] = None if deps is None else {v.name for v in deps if v.name in inputs}
    for v in md.modelVariables:  # an output the model structure does not list: every input
        if v.causality == "output" and v.name not in out:
            out[v.name] = None
    # the element connectors of FMI 3.0 arrays (z[1], ...) depend, and are depended on, as their array
    elements = getattr(comp, "elements", {})
    for deps in out.values():
        if deps is not None:
            deps |= {e for e, (array, _, _) in elements.items() if array in deps}
    out.update({e: out[array] for e, (array, _, _) in elements.items() if array in out})
    return out


def _depends(ft, output, input_) -> bool:
    deps = ft.get(output, None)
    return deps is None or input_ in deps


def variable_edges(system) -> Dict[Tuple[str, str], List[Tuple[str, str]]]:
    """Edges between (component, variable) nodes: a connection output -> input, and inside a
    component an input -> each output that depends on it directly."""
    edges: Dict[Tuple[str, str], List[Tuple[str, str]]] = {}
    ft = {n: feedthrough(c) for n, c in system.components.items() if c.model_description is not None}
    for c in system.connections:
        edges.setdefault((c.start_element, c.start_connector), []).append((c.end_element, c.end_connector))
    for name, comp in system.components.items():
        if name not in ft:
            continue
        fed = [c.end_connector for c in system.connections if c.end_element == name]
        for i in fed:
            for o in ft[name]:
                if _depends(ft[name], o, i):
                    edges.setdefault((name, i), []).append((name, o))
    return edges


def algebraic_loop(system) -> Optional[List[Tuple[str, str]]]:
    """One algebraic loop as the cycle of its variables, or None."""
    edges = variable_edges(system)
    state: Dict[Tuple[str, str], int] = {}  # 1 on the path, 2 done
    path: List[Tuple[str, str]] = []

    def visit(node):
        state[node] = 1
        path.append(node)
        for nxt in edges.get(node, []):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if state.get(nxt) is None:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return None

    for node in list(edges):
        if state.get(node) is None:
            found = visit(node)
            if found:
                return found
    return None


def loop_text(cycle) -> str:
    return " -> ".join(f"{c}.{v}" for c, v in cycle)


def update_order(system, fallback: List[str]) -> List[str]:
    """The components in an order where each one comes after every component that feeds one of
    its direct feed-through inputs; ties (and the members of an algebraic loop) in ``fallback``
    order."""
    ft = {n: feedthrough(c) for n, c in system.components.items() if c.model_description is not None}
    if len(ft) != len(system.components):
        return list(fallback)
    after: Dict[str, Set[str]] = {n: set() for n in fallback}  # component -> components it waits for
    for c in system.connections:
        if c.start_element == c.end_element:
            continue
        b = ft.get(c.end_element, {})
        if any(_depends(b, o, c.end_connector) for o in b):
            after[c.end_element].add(c.start_element)
    order, done = [], set()
    while len(order) < len(fallback):
        ready = [n for n in fallback if n not in done and after[n] <= done]
        if not ready:  # an algebraic loop: take the next one in the fallback order
            ready = [n for n in fallback if n not in done][:1]
        order.append(ready[0])
        done.add(ready[0])
    return order
