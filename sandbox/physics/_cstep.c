/* One control period of a batch of pymunk worlds in one C call.
 *
 * sandbox/physics/stepping.py (WorldStepper) calls advance() once per control period
 * when no world of the batch has an open contact episode. It makes the C calls the
 * Python path makes, in the same order and with the same arguments: Chipmunk's
 * cpSpaceEachBody with pymunk's batched set iterator on every live world's control
 * space (the commands), then for each substep the batch's clock is written and
 * cpSpaceStep is called on every live world's space, then cpSpaceEachBody with the
 * batched get iterator on every space (the state). Nothing here is linked against
 * Chipmunk or includes its headers: the functions come as addresses taken from
 * pymunk's own cffi module (ffi.addressof(lib, ...)), the spaces and the iterators'
 * data as addresses of the records pymunk and the stepper already hold.
 *
 * The clock is two doubles the Python begin callback reads (World._clock): [0] the
 * start time of the substep being stepped [s], [1] raised (nonzero) by the callback
 * when it opens a contact episode. When it is raised after a substep, advance()
 * returns at once, before the next substep and before the state is read: open
 * episodes must be updated between substeps, which the Python path then does.
 */

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>

/* cpSpaceStep(cpSpace *, cpFloat) with cpFloat a double, as pymunk builds Chipmunk. */
typedef void (*step_fn)(void *space, double dt);
/* cpSpaceBodyIteratorFunc: void (*)(cpBody *, void *). */
typedef void (*body_fn)(void *body, void *data);
/* cpSpaceEachBody(cpSpace *, cpSpaceBodyIteratorFunc, void *). */
typedef void (*each_fn)(void *space, body_fn func, void *data);

static void
each_body(each_fn each, body_fn func, void *const *spaces, void *const *data,
          Py_ssize_t count)
{
    for (Py_ssize_t i = 0; i < count; i++) {
        each(spaces[i], func, data[i]);
    }
}

PyDoc_STRVAR(advance_doc,
"advance(step, each, set, get, spaces, controls, writes, reads, count, substeps,\n"
"        t0, dt, clock, write_arrays, read_arrays, arrays, size, num_at) -> int\n"
"\n"
"One control period of ``count`` worlds; every pointer argument is an address\n"
"(int). ``step``: cpSpaceStep; ``each``: cpSpaceEachBody; ``set``, ``get``:\n"
"pymunk's batched body iterators; ``spaces``, ``controls``, ``writes``, ``reads``:\n"
"arrays of ``count`` addresses (the worlds' spaces, control spaces and the\n"
"iterators' pmBatchedData); ``clock``: two doubles. First the ``num`` field (an\n"
"int at byte ``num_at``) of each of the ``arrays`` pmFloatArray records of\n"
"``size`` bytes at ``write_arrays`` and at ``read_arrays`` is set to 0, and\n"
"``clock[1]`` to 0. Substep s starts at ``t0 + s * dt``, computed as Python\n"
"computes it. Returns the substeps stepped: ``substeps``, the state read, unless\n"
"``clock[1]`` was raised after one (then the substeps stepped so far, the state\n"
"not read).");

/* The ``num`` field of ``arrays`` records of ``size`` bytes from ``block``, to 0. */
static void
clear_nums(uintptr_t block, Py_ssize_t arrays, Py_ssize_t size, Py_ssize_t num_at)
{
    for (Py_ssize_t i = 0; i < arrays; i++) {
        *(int *)(block + (uintptr_t)(i * size + num_at)) = 0;
    }
}

static PyObject *
advance(PyObject *self, PyObject *args)
{
    unsigned long long step_addr, each_addr, set_addr, get_addr;
    unsigned long long spaces_addr, controls_addr, writes_addr, reads_addr;
    unsigned long long clock_addr, write_block, read_block;
    Py_ssize_t count, arrays, size, num_at;
    int substeps;
    double t0, dt;

    if (!PyArg_ParseTuple(args, "KKKKKKKKniddKKKnnn:advance", &step_addr, &each_addr,
                          &set_addr, &get_addr, &spaces_addr, &controls_addr,
                          &writes_addr, &reads_addr, &count, &substeps, &t0, &dt,
                          &clock_addr, &write_block, &read_block, &arrays, &size,
                          &num_at)) {
        return NULL;
    }
    step_fn step = (step_fn)(uintptr_t)step_addr;
    each_fn each = (each_fn)(uintptr_t)each_addr;
    body_fn set = (body_fn)(uintptr_t)set_addr;
    body_fn get = (body_fn)(uintptr_t)get_addr;
    void *const *spaces = (void *const *)(uintptr_t)spaces_addr;
    void *const *controls = (void *const *)(uintptr_t)controls_addr;
    void *const *writes = (void *const *)(uintptr_t)writes_addr;
    void *const *reads = (void *const *)(uintptr_t)reads_addr;
    double *clock = (double *)(uintptr_t)clock_addr;

    clear_nums((uintptr_t)write_block, arrays, size, num_at);
    clear_nums((uintptr_t)read_block, arrays, size, num_at);
    clock[1] = 0.0;
    each_body(each, set, controls, writes, count);
    for (int s = 0; s < substeps; s++) {
        /* t0 + s * dt rounded after each operation, as Python does: the volatile
           product cannot be fused with the sum into one multiply-add. */
        volatile double offset = (double)s * dt;
        clock[0] = t0 + offset;
        for (Py_ssize_t i = 0; i < count; i++) {
            step(spaces[i], dt);
        }
        if (clock[1] != 0.0) {
            return PyLong_FromLong(s + 1);
        }
    }
    each_body(each, get, spaces, reads, count);
    return PyLong_FromLong(substeps);
}

static PyMethodDef methods[] = {
    {"advance", advance, METH_VARARGS, advance_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    "_cstep",
    "One control period of a batch of pymunk worlds in one C call "
    "(see sandbox.physics.stepping).",
    -1,
    methods,
};

PyMODINIT_FUNC
PyInit__cstep(void)
{
    return PyModule_Create(&module);
}
