"""Generated mutants that survive the graders, reviewed: each is equivalent to the reference
for every input the contract allows, or changes only what the contract leaves free (the
docstring then says so). ``rtcourse mutants --generated`` counts these as neither killed
nor survived. Ids are ``module:function:kind:n`` (see course.grading.mutate)."""

EQUIVALENT = {
    # Lab 2
    "lab2_accel:build_lbvh:const_int:34":
        "an inner node's 'first' is never read (only leaves hold triangles[first:first + "
        "count], and count is 0 for inner nodes), so 1 instead of 0 there changes nothing",
    "lab2_accel:kd_pack:const_int:10":
        "packed - 2**33 instead of packed - 2**32 before .to(torch.int32): the conversion "
        "keeps the low 32 bits, the same for both",
    "lab2_accel:bvh_closest_hit_fast:bool_And_Or:3":
        "compacting the rays at every look instead of only when few run changes only the "
        "order in which unfinished rays are stepped, not their hits or counters",
}
