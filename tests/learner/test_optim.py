"""The learner's RMSprop and Adam take the same steps as torch.optim's."""

import pytest
import torch

from learner.network import QNetwork
from learner.optim import Adam, RMSprop


def trajectories(make_mine, make_theirs, steps: int = 5) -> tuple[list, list]:
    torch.manual_seed(0)
    mine_net = QNetwork()
    theirs_net = QNetwork()
    theirs_net.load_state_dict(mine_net.state_dict())
    images = torch.rand(8, 3, 64, 64)
    results = []
    for net, make in ((mine_net, make_mine), (theirs_net, make_theirs)):
        optimizer = make(net.parameters())
        for _ in range(steps):
            optimizer.zero_grad()
            net(images).square().mean().backward()
            optimizer.step()
        results.append([p.detach().clone() for p in net.parameters()])
    return results[0], results[1]


@pytest.mark.parametrize(
    ("make_mine", "make_theirs"),
    [
        (
            lambda p: RMSprop(p, lr=1e-3, alpha=0.9, eps=1e-7),
            lambda p: torch.optim.RMSprop(p, lr=1e-3, alpha=0.9, eps=1e-7),
        ),
        (lambda p: Adam(p, lr=1e-3, eps=1e-7), lambda p: torch.optim.Adam(p, lr=1e-3, eps=1e-7)),
    ],
    ids=["rmsprop", "adam"],
)
def test_same_steps_as_torch_optim(make_mine, make_theirs) -> None:
    mine, theirs = trajectories(make_mine, make_theirs)
    for a, b in zip(mine, theirs, strict=True):
        assert torch.allclose(a, b, rtol=1e-5, atol=1e-7)
    assert not torch.equal(mine[0], trajectories(make_mine, make_theirs, steps=0)[0][0])


def test_state_round_trip_continues_identically() -> None:
    torch.manual_seed(1)
    net = QNetwork()
    optimizer = Adam(net.parameters(), lr=1e-3, eps=1e-7)
    images = torch.rand(4, 3, 64, 64)
    for _ in range(2):
        optimizer.zero_grad()
        net(images).sum().backward()
        optimizer.step()
    copy = QNetwork()
    copy.load_state_dict(net.state_dict())
    other = Adam(copy.parameters(), lr=1e-3, eps=1e-7)
    other.load_state_dict(optimizer.state_dict())
    for model, opt in ((net, optimizer), (copy, other)):
        opt.zero_grad()
        model(images).sum().backward()
        opt.step()
    assert all(torch.equal(a, b) for a, b in zip(net.parameters(), copy.parameters(), strict=True))
