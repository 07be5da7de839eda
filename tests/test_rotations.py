"""Rotation conversions in torch: round trips, orthonormality, finite gradients at the identity."""
import pytest
import torch
from scipy.spatial.transform import Rotation

from fingersplat3d.rotations import axis_angle_to_matrix, matrix_to_quaternion, quaternion_to_matrix


@pytest.mark.gradcheck
def test_rodrigues_gradients_float64_including_zero():
    for omega in (torch.zeros(3), torch.tensor([1e-9, -2e-9, 0.0]), torch.tensor([0.3, -1.2, 2.0])):
        omega = omega.double().requires_grad_(True)
        assert torch.autograd.gradcheck(axis_angle_to_matrix, (omega,), eps=1e-6, atol=1e-6)
    rotation = axis_angle_to_matrix(torch.tensor([0.3, -1.2, 2.0], dtype=torch.float64))
    assert torch.allclose(rotation @ rotation.T, torch.eye(3, dtype=torch.float64), atol=1e-12)


def test_axis_angle_and_quaternions_agree_with_scipy():
    vectors = torch.tensor([[0.3, -1.2, 2.0], [1e-10, 0.0, 0.0], [0.0, 3.1, 0.0]], dtype=torch.float64)
    expected = torch.as_tensor(Rotation.from_rotvec(vectors.numpy()).as_matrix())
    assert torch.allclose(axis_angle_to_matrix(vectors), expected, atol=1e-12)
    quats = matrix_to_quaternion(expected)
    assert torch.allclose(quaternion_to_matrix(quats), expected, atol=1e-12)
    wxyz = torch.as_tensor(Rotation.from_rotvec(vectors.numpy()).as_quat(scalar_first=True))
    wxyz = torch.where(wxyz[:, :1] < 0, -wxyz, wxyz)
    assert torch.allclose(quats, wxyz, atol=1e-12)


def test_rotation_angle_is_the_axis_angle_magnitude_with_a_gradient():
    from fingersplat3d.rotations import rotation_angle

    omega = torch.tensor([[0.3, -0.2, 0.1], [1e-8, 0.0, 0.0], [0.0, 3.0, 0.0]], dtype=torch.float64, requires_grad=True)
    angle = rotation_angle(axis_angle_to_matrix(omega), torch.eye(3, dtype=torch.float64))
    assert torch.allclose(angle, omega.detach().norm(dim=1), rtol=1e-12, atol=1e-15)
    angle[0].backward()  # away from 0 the angle is differentiable: d|omega|/d omega = omega / |omega|
    assert torch.allclose(omega.grad[0], omega.detach()[0] / omega.detach()[0].norm())
