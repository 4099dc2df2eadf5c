"""bench.nrt_loops finds the reference counting that numba left on a cycle of a function's
control flow, and only there."""

from __future__ import annotations

from bench.nrt_loops import function_blocks, loop_blocks, refcounts_in_loops

IR = """
define i32 @cpython.kernel(ptr %a) {
entry:
  call void @NRT_incref(ptr %a)
  ret i32 0
}

define i32 @_ZN6module6kernelE(ptr %a, ptr %b) {
entry:
  call void @NRT_incref(ptr %arg.a.0)
  br label %B10
B10:
  %i = phi i64 [ 0, %entry ], [ %j, %B20.endif ]
  call void @NRT_incref(ptr nonnull %.7.i.i)
  br i1 %c, label %B20.endif, label %B30
B20.endif:
  call void @NRT_decref(ptr nonnull %.7.i.i)
  %j = add i64 %i, 1
  br i1 %d, label %B10, label %B40
B30:
  br label %B30.self
B30.self:
  call void @NRT_decref(ptr %arg.b.0)
  br i1 %e, label %B30.self, label %B40
B40:
  call void @NRT_decref(ptr %arg.a.0)
  ret i32 0
}
"""


def test_loop_blocks_are_the_cycles_of_the_control_flow() -> None:
    blocks = function_blocks(IR, "kernel")
    assert list(blocks) == ["entry", "B10", "B20.endif", "B30", "B30.self", "B40"]
    assert loop_blocks(blocks) == {"B10", "B20.endif", "B30.self"}


def test_refcounts_in_loops_name_the_blocks_and_values() -> None:
    found = refcounts_in_loops(IR, "kernel")
    assert found == [("B10", [("incref", "%.7.i.i")]), ("B20.endif", [("decref", "%.7.i.i")]),
                     ("B30.self", [("decref", "%arg.b.0")])]
